// Loads a vocabulary saved by DBoW2's TemplatedVocabulary::save() (the same YAML layout) in
// linear time. DBoW2's own load() reads the node list with FileNode::operator[](i), which is
// linear in i in OpenCV 4, so a 323k-word vocabulary took two hours to load; here the lists are
// walked with FileNodeIterator. Our own code: a subclass filling the protected members.
#pragma once

#include <string>

#include <opencv2/core.hpp>

#include "TemplatedVocabulary.h"

template <class TDescriptor, class F>
class FastLoadVocabulary : public DBoW2::TemplatedVocabulary<TDescriptor, F> {
    using Base = DBoW2::TemplatedVocabulary<TDescriptor, F>;

public:
    /// Throws std::string when the file cannot be opened or is not a vocabulary.
    void loadFast(const std::string &filename, const std::string &name = "vocabulary")
    {
        cv::FileStorage fs(filename, cv::FileStorage::READ);
        if (!fs.isOpened())
            throw std::string("Could not open file ") + filename;
        cv::FileNode fvoc = fs[name];
        if (fvoc.empty() || fvoc["nodes"].empty() || fvoc["words"].empty())
            throw std::string("no DBoW2 vocabulary '") + name + "' in " + filename;
        this->m_words.clear();
        this->m_nodes.clear();
        this->m_k = (int)fvoc["k"];
        this->m_L = (int)fvoc["L"];
        this->m_scoring = (DBoW2::ScoringType)((int)fvoc["scoringType"]);
        this->m_weighting = (DBoW2::WeightingType)((int)fvoc["weightingType"]);
        this->createScoringObject();

        cv::FileNode nodes = fvoc["nodes"];
        this->m_nodes.resize(nodes.size() + 1); // + the root
        this->m_nodes[0].id = 0;
        for (cv::FileNodeIterator it = nodes.begin(); it != nodes.end(); ++it) {
            const cv::FileNode n = *it;
            const DBoW2::NodeId nid = (int)n["nodeId"];
            const DBoW2::NodeId pid = (int)n["parentId"];
            if (nid >= this->m_nodes.size() || pid >= this->m_nodes.size())
                throw std::string("bad node id in ") + filename;
            auto &node = this->m_nodes[nid];
            node.id = nid;
            node.parent = pid;
            node.weight = (DBoW2::WordValue)(double)n["weight"];
            this->m_nodes[pid].children.push_back(nid);
            F::fromString(node.descriptor, (std::string)n["descriptor"]);
        }

        cv::FileNode words = fvoc["words"];
        this->m_words.resize(words.size());
        for (cv::FileNodeIterator it = words.begin(); it != words.end(); ++it) {
            const cv::FileNode w = *it;
            const DBoW2::WordId wid = (int)w["wordId"];
            const DBoW2::NodeId nid = (int)w["nodeId"];
            if (wid >= this->m_words.size() || nid >= this->m_nodes.size())
                throw std::string("bad word id in ") + filename;
            this->m_nodes[nid].word_id = wid;
            this->m_words[wid] = &this->m_nodes[nid];
        }
    }
};
