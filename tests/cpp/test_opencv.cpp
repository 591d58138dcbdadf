// Tests of the OpenCV conveniences (include/topoloc_opencv.hpp): cv::Mat descriptors and images,
// ROIs, type checks, and maps built from Mats. Built and run by tests/cpp/run.sh when OpenCV 4 is
// installed. topoloc_opencv.hpp comes first: it must bring in everything it needs by itself.

#include "topoloc_opencv.hpp"
#include "topoloc.hpp" // after it: harmless

#include "harness.hpp"

namespace {

TEST(opencv_overloads)
{
    const topoloc::Map map = chain_map();
    topoloc::Localizer localizer(map);
    std::vector<float> d = observe(2, 0);
    const cv::Mat row(1, static_cast<int>(kDim), CV_32F, d.data());
    CHECK_EQ(topoloc::process_descriptor(localizer, row, 0.0).place, uint32_t{2});
    const cv::Mat col(static_cast<int>(kDim), 1, CV_32F, d.data());
    CHECK_EQ(topoloc::process_descriptor(localizer, col, 0.1).place, uint32_t{2});
    CHECK_THROWS_STATUS(
        topoloc::process_descriptor(localizer, cv::Mat(1, static_cast<int>(kDim), CV_64F), 0.2),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_THROWS_STATUS(
        topoloc::process_descriptor(localizer, cv::Mat(8, 8, CV_32F, d.data()), 0.2),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_THROWS_STATUS(topoloc::process_descriptor(localizer, cv::Mat(), 0.2),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
    const cv::Mat wide(4, static_cast<int>(kDim), CV_32F, cv::Scalar(1.0));
    CHECK_THROWS_STATUS(topoloc::process_descriptor(localizer, wide.col(0), 0.2),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
    topoloc::MapBuilder builder("test", "", kDim);
    CHECK_EQ(topoloc::add_view(builder, builder.add_place(), row), uint32_t{0});
}

TEST(opencv_images)
{
    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    topoloc::Localizer localizer(image_map(), options);
    std::vector<uint8_t> revisit = revisit_pixels(places_pixels()[4], 11);
    const topoloc::Result reference = localizer.process(gray(revisit), 0.0); // a copy
    CHECK_EQ(reference.place, uint32_t{4});
    auto same_as_reference = [&](const topoloc::Result &r) {
        return r.place == reference.place && std::abs(r.similarity - reference.similarity) < 1e-4f;
    };

    // CV_8UC1, continuous.
    const cv::Mat grey(int(kImgH), int(kImgW), CV_8UC1, revisit.data());
    CHECK(same_as_reference(topoloc::process_image(localizer, grey, 0.0)));

    // A non-continuous ROI of a larger grey image: its step is honoured, nothing is copied.
    cv::Mat big(int(kImgH) + 20, int(kImgW) + 30, CV_8UC1, cv::Scalar(0));
    const cv::Rect rect(10, 5, int(kImgW), int(kImgH));
    grey.copyTo(big(rect));
    const cv::Mat roi = big(rect);
    CHECK(!roi.isContinuous());
    CHECK(roi.step[0] != std::size_t(roi.cols) * roi.elemSize());
    const topoloc::Image view = topoloc::image_view(roi);
    CHECK(view.data == roi.data && view.format == TOPOLOC_PIXEL_GRAY8);
    CHECK_EQ(view.stride, std::size_t{kImgW + 30});
    CHECK_EQ(view.data_len, std::size_t{(kImgW + 30) * (kImgH - 1) + kImgW});
    CHECK(same_as_reference(topoloc::process_image(localizer, roi, 0.0)));

    // CV_8UC3 (BGR) and CV_8UC4 (BGRA), also as ROIs.
    cv::Mat bgr, bgra;
    cv::merge(std::vector<cv::Mat>{grey, grey, grey}, bgr);
    cv::merge(
        std::vector<cv::Mat>{grey, grey, grey, cv::Mat(grey.size(), CV_8UC1, cv::Scalar(255))},
        bgra);
    CHECK(topoloc::image_view(bgr).format == TOPOLOC_PIXEL_BGR8);
    CHECK(topoloc::image_view(bgra).format == TOPOLOC_PIXEL_BGRA8);
    CHECK(same_as_reference(topoloc::process_image(localizer, bgr, 0.0)));
    CHECK(same_as_reference(topoloc::process_image(localizer, bgra, 0.0)));
    cv::Mat big_bgr(int(kImgH) + 4, int(kImgW) + 8, CV_8UC3, cv::Scalar(1, 2, 3));
    bgr.copyTo(big_bgr(cv::Rect(7, 3, int(kImgW), int(kImgH))));
    const cv::Mat roi_bgr = big_bgr(cv::Rect(7, 3, int(kImgW), int(kImgH)));
    CHECK(!roi_bgr.isContinuous());
    CHECK_EQ(topoloc::image_view(roi_bgr).stride, std::size_t{(kImgW + 8) * 3});
    CHECK(same_as_reference(topoloc::process_image(localizer, roi_bgr, 0.0)));

    // Other types are refused before the library sees them; the localizer is unchanged.
    const uint64_t frames = localizer.last_result().frame_index;
    CHECK_THROWS_STATUS(
        topoloc::process_image(localizer, cv::Mat(10, 10, CV_16UC1, cv::Scalar(0)), 1.0),
        TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_THROWS_STATUS(
        topoloc::process_image(localizer, cv::Mat(10, 10, CV_32FC3, cv::Scalar(0)), 1.0),
        TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_THROWS_STATUS(
        topoloc::process_image(localizer, cv::Mat(10, 10, CV_8UC2, cv::Scalar(0)), 1.0),
        TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_THROWS_STATUS(topoloc::process_image(localizer, cv::Mat(), 1.0),
                        TOPOLOC_ERR_INVALID_IMAGE);
    const int sizes[3] = {4, 4, 4};
    CHECK_THROWS_STATUS(
        topoloc::process_image(localizer, cv::Mat(3, sizes, CV_8UC1, cv::Scalar(0)), 1.0),
        TOPOLOC_ERR_INVALID_IMAGE);
    try {
        (void)topoloc::image_view(cv::Mat(2, 2, CV_64F));
    } catch (const topoloc::InvalidImageError &e) {
        CHECK(e.message().find("CV_8UC1") != std::string::npos);
    }
    // A constant Mat is a valid image without content.
    CHECK_THROWS_STATUS(
        topoloc::process_image(
            localizer, cv::Mat(int(kImgH), int(kImgW), CV_8UC3, cv::Scalar(40, 40, 40)), 1.0),
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    CHECK_EQ(localizer.last_result().frame_index, frames);

    // Maps from Mats (ROIs included) equal maps from the same pixels as plain views.
    std::vector<cv::Mat> mats;
    std::vector<cv::Mat> owners;
    for (uint32_t p = 0; p < 4; ++p) {
        cv::Mat parent(int(kImgH) + 2, int(kImgW) + 2, CV_8UC1, cv::Scalar(0));
        cv::Mat(int(kImgH), int(kImgW), CV_8UC1, const_cast<uint8_t *>(places_pixels()[p].data()))
            .copyTo(parent(cv::Rect(1, 1, int(kImgW), int(kImgH))));
        owners.push_back(parent);
        mats.push_back(parent(cv::Rect(1, 1, int(kImgW), int(kImgH))));
    }
    const topoloc::Map from_mats =
        topoloc::Map::build_from_images(topoloc::image_views(mats), vlad_options(4));
    const topoloc::Map from_views =
        topoloc::Map::build_from_images(place_images(4), vlad_options(4));
    CHECK(from_mats.descriptor_model() == from_views.descriptor_model());
    CHECK(from_mats.view_descriptor(2) == from_views.view_descriptor(2));
    mats.push_back(cv::Mat(8, 8, CV_16UC1));
    const std::string bad_message = CHECK_THROWS_STATUS(
        topoloc::Map::build_from_images(topoloc::image_views(mats), vlad_options(5)),
        TOPOLOC_ERR_INVALID_IMAGE);
    CHECK(bad_message.find("images[4]") == 0);
}

} // namespace

int main() { return run_all_tests(); }
