/*
 * topoloc/keyframes.hpp: `KeyframeDescriber`, which turns keyframe images into what a loop
 * detector needs, a map's global descriptor and local features of one kind, in one pass
 * (ABI 1.15; part of topoloc.hpp, which has the overview; its options and `LocalFeatures` are in
 * options.hpp; `LoopDetector::add_image` in loops.hpp takes it).
 */

#ifndef TOPOLOC_KEYFRAMES_HPP
#define TOPOLOC_KEYFRAMES_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "map.hpp"

namespace topoloc {

/// Owner of a keyframe describer (`topoloc_keyframe_describer*`, ABI 1.15): `map`'s describer
/// (the global descriptor, exactly as the map's views were described) and local features of one
/// kind (`LocalFeatures`: XFeat by default, ORB, or the describer's own CNN cells), for
/// `LoopDetector::add_image`, so that a host with keyframe images, not its own keypoints, gets
/// verified loop hints. Move-only; the destructor calls `topoloc_keyframe_describer_free`; it
/// does not keep the map.
///
/// Thread safety: single-threaded state; use from one thread at a time (it may move between
/// threads); a call made while another thread uses it throws `Error` with
/// `TOPOLOC_ERR_CONCURRENT_USE` and changes nothing.
/// Errors: every method that calls the library throws `Error` (or its status subclass).
class KeyframeDescriber
    : public detail::Owner<topoloc_keyframe_describer, &topoloc_keyframe_describer_free> {
public:
    /// An empty owner (`!describer`).
    KeyframeDescriber() noexcept = default;

    /// Takes ownership of `raw` (from `topoloc_keyframe_describer_new`); null gives an empty
    /// owner.
    explicit KeyframeDescriber(topoloc_keyframe_describer *raw) noexcept : Owner(raw) {}

    /// Loads `map`'s describer and the local features `options` names (for XFeat: its network;
    /// for ONNX maps the runtime and the model, checked by hash). A detector made
    /// `LoopDetector::from_map` takes the map's kind of local features (`ImageMapOptions::
    /// local_features` when it was built): give the same here. Throws `NoDescriberError` (a map
    /// built from descriptors), `BackendUnavailableError` (a missing runtime or model: the paths
    /// tried and what to install in the message), `ModelError` (a file that is not the expected
    /// network), `Error` (`TOPOLOC_ERR_DESCRIPTOR_MISMATCH` for another backend or model than the
    /// map's; `_INVALID_OPTION` for an unknown local-features or backend value, threads out of
    /// range, or cells on a VLAD map; `_STRUCT_SIZE`; `_NULL_ARGUMENT` for an empty map).
    explicit KeyframeDescriber(const Map &map, const KeyframeDescriberOptions &options =
                                                   default_keyframe_describer_options())
    {
        topoloc_keyframe_describer *raw = nullptr;
        check(topoloc_keyframe_describer_new(map.capi(), &options, &raw));
        adopt(raw);
    }

    // Moves (noexcept; the source is left empty) and the destructor (calls
    // `topoloc_keyframe_describer_free`) come from `detail::Owner`; copies are deleted.

    /// The local features it extracts. Throws `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    [[nodiscard]] LocalFeatures local_features() const
    {
        return static_cast<LocalFeatures>(read_value(&topoloc_keyframe_describer_local_features));
    }
};

} // namespace topoloc

#endif // TOPOLOC_KEYFRAMES_HPP
