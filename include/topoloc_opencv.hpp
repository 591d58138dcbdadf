/*
 * topoloc_opencv.hpp: OpenCV conveniences for the C++ layer (topoloc.hpp), for hosts that use
 * OpenCV. Include this header instead of (or as well as, in any order) topoloc.hpp; it includes
 * topoloc.hpp and <opencv2/core.hpp> itself, and adds only free functions, so the classes of
 * topoloc.hpp are the same in every translation unit whatever is included first.
 *
 * Images are 8-bit `cv::Mat`s: CV_8UC1 (grey), CV_8UC3 (BGR, OpenCV's channel order) or CV_8UC4
 * (BGRA), two-dimensional and non-empty, with any row step (ROIs of larger images work without
 * a copy). Descriptors are non-empty, continuous 1xD or Dx1 CV_32F matrices. Every function
 * borrows the Mat only for the duration of the call (or, for `image_view`, for as long as the
 * returned view is used), and is as thread-safe as the topoloc object it is given.
 *
 * Link with OpenCV's core module (`pkg-config --libs opencv4`, or `opencv_core` in CMake).
 */

#ifndef TOPOLOC_OPENCV_HPP
#define TOPOLOC_OPENCV_HPP

#include "topoloc.hpp"

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace topoloc {

/// A view of an 8-bit OpenCV image (see the top of this header for the accepted types). The
/// Mat must outlive the view's use; nothing is copied. Throws `InvalidImageError` for any other
/// type, an empty Mat, or a Mat of more than two dimensions.
[[nodiscard]] inline Image image_view(const cv::Mat &mat)
{
    uint32_t format = TOPOLOC_PIXEL_NONE;
    switch (mat.type()) {
    case CV_8UC1:
        format = TOPOLOC_PIXEL_GRAY8;
        break;
    case CV_8UC3:
        format = TOPOLOC_PIXEL_BGR8;
        break;
    case CV_8UC4:
        format = TOPOLOC_PIXEL_BGRA8;
        break;
    default:
        break;
    }
    if (format == TOPOLOC_PIXEL_NONE || mat.dims != 2 || mat.empty()) {
        throw InvalidImageError(
            TOPOLOC_ERR_INVALID_IMAGE,
            "image cv::Mat must be a non-empty 2-D CV_8UC1 (grey), CV_8UC3 (BGR) or CV_8UC4 (BGRA) "
            "matrix, got type " +
                std::to_string(mat.type()) + " with " + std::to_string(mat.dims) + " dimensions");
    }
    const std::size_t step = mat.step[0];
    const std::size_t row = static_cast<std::size_t>(mat.cols) * mat.elemSize();
    return image_view(mat.data, step * static_cast<std::size_t>(mat.rows - 1) + row,
                      static_cast<uint32_t>(mat.cols), static_cast<uint32_t>(mat.rows), format,
                      step);
}

/// Views of several 8-bit OpenCV images, for `Map::build_from_images(image_views(mats), ...)`.
/// Throws `InvalidImageError` naming the first unusable Mat (`images[i]`).
[[nodiscard]] inline std::vector<Image> image_views(const std::vector<cv::Mat> &images)
{
    std::vector<Image> views;
    views.reserve(images.size());
    for (std::size_t i = 0; i < images.size(); ++i) {
        try {
            views.push_back(image_view(images[i]));
        } catch (const InvalidImageError &e) {
            throw InvalidImageError(TOPOLOC_ERR_INVALID_IMAGE,
                                    "images[" + std::to_string(i) + "]: " + e.message());
        }
    }
    return views;
}

/// The floats of a descriptor held in a cv::Mat: `{data, D}`, borrowed from the Mat. Throws
/// `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT`) unless the Mat is a non-empty, continuous 1xD or
/// Dx1 CV_32F matrix.
[[nodiscard]] inline std::pair<const float *, std::size_t> descriptor_view(const cv::Mat &mat)
{
    if (mat.empty() || mat.dims != 2 || mat.type() != CV_32FC1 || !mat.isContinuous() ||
        (mat.rows != 1 && mat.cols != 1)) {
        throw Error(TOPOLOC_ERR_INVALID_ARGUMENT,
                    "descriptor cv::Mat must be a non-empty, continuous 1xD or Dx1 CV_32F matrix");
    }
    return {mat.ptr<float>(), mat.total()};
}

/// `localizer.process` of a frame given by its descriptor in a cv::Mat (see `descriptor_view`;
/// a bad Mat throws `Error` with `TOPOLOC_ERR_INVALID_ARGUMENT` and leaves the localizer
/// unchanged). Same result lifetime and errors as `Localizer::process`.
[[nodiscard]] inline const Result &process_descriptor(Localizer &localizer,
                                                      const cv::Mat &descriptor, double timestamp,
                                                      const double *odometry = nullptr)
{
    const auto d = descriptor_view(descriptor);
    return localizer.process(d.first, d.second, timestamp, odometry);
}

/// `localizer.process` of a frame given by its 8-bit camera image in a cv::Mat (see
/// `image_view`; another type throws `InvalidImageError` and leaves the localizer unchanged).
/// Same result lifetime and errors as `Localizer::process` of an `Image`.
[[nodiscard]] inline const Result &process_image(Localizer &localizer, const cv::Mat &image,
                                                 double timestamp, const double *odometry = nullptr)
{
    return localizer.process(image_view(image), timestamp, odometry);
}

/// `builder.add_view` with a descriptor in a cv::Mat (see `descriptor_view`); returns the view
/// id. Throws as `MapBuilder::add_view`, and `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT`) for a bad
/// Mat.
inline uint32_t add_view(MapBuilder &builder, uint32_t place, const cv::Mat &descriptor,
                         const ViewAttributes &attributes = ViewAttributes())
{
    const auto d = descriptor_view(descriptor);
    return builder.add_view(place, d.first, d.second, attributes);
}

} // namespace topoloc

#endif // TOPOLOC_OPENCV_HPP
