/*
 * topoloc/image.hpp: borrowed views of camera images, for map builds, image frames and
 * describers, and of registered depth images, for image keyframes (part of topoloc.hpp, which
 * has the overview; `cv::Mat` views are in topoloc_opencv.hpp).
 */

#ifndef TOPOLOC_IMAGE_HPP
#define TOPOLOC_IMAGE_HPP

#include "../topoloc.h"
#include "error.hpp"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace topoloc {

/// A borrowed image (the C struct): `height` rows of `stride` bytes at `data`, each starting
/// with `width` pixels of `format` (a `TOPOLOC_PIXEL_*` value); `data_len` bytes are readable.
/// The pixels are read only during the call the image is passed to. Make one with
/// `image_view`; a value-initialised `Image{}` means "no image" (`TOPOLOC_PIXEL_NONE`).
using Image = topoloc_image;

/// Bytes per pixel of a `TOPOLOC_PIXEL_*` format; 0 for `TOPOLOC_PIXEL_NONE` and unknown values.
[[nodiscard]] constexpr std::size_t pixel_bytes(uint32_t format) noexcept
{
    return format == TOPOLOC_PIXEL_GRAY8                                    ? 1
           : format == TOPOLOC_PIXEL_RGB8 || format == TOPOLOC_PIXEL_BGR8   ? 3
           : format == TOPOLOC_PIXEL_RGBA8 || format == TOPOLOC_PIXEL_BGRA8 ? 4
                                                                            : 0;
}

/// A view of `data_len` bytes holding `width` x `height` pixels of `format` in rows `stride`
/// bytes apart (all checked by the library when the image is used).
[[nodiscard]] inline Image image_view(const void *data, std::size_t data_len, uint32_t width,
                                      uint32_t height, uint32_t format, std::size_t stride) noexcept
{
    Image image{};
    image.data = static_cast<const uint8_t *>(data);
    image.data_len = data_len;
    image.width = width;
    image.height = height;
    image.stride = stride;
    image.format = format;
    return image;
}

/// A view of `width` x `height` pixels of `format` at `data`, rows `stride` bytes apart
/// (0 = packed rows of `width * pixel_bytes(format)`). The caller promises that
/// `stride * (height - 1) + width * pixel_bytes(format)` bytes are readable at `data`, which
/// becomes `data_len`. Throws `InvalidImageError` for an unknown format or a size whose byte
/// count overflows; everything else (zero sizes, a stride shorter than a row, sizes above the
/// library's limit) is judged by the library when the image is used.
[[nodiscard]] inline Image image_view(const void *data, uint32_t width, uint32_t height,
                                      uint32_t format, std::size_t stride = 0)
{
    const std::size_t bytes = pixel_bytes(format);
    if (bytes == 0) {
        throw InvalidImageError(TOPOLOC_ERR_INVALID_IMAGE,
                                "image format " + std::to_string(format) +
                                    " is not a TOPOLOC_PIXEL_* format with pixels");
    }
    const std::size_t row = static_cast<std::size_t>(width) * bytes;
    if (stride == 0) {
        stride = row;
    }
    std::size_t len = 0;
    if (width != 0 && height != 0) {
        const std::size_t max = std::numeric_limits<std::size_t>::max();
        if (height - 1 > 0 && stride > (max - row) / (height - 1)) {
            throw InvalidImageError(TOPOLOC_ERR_INVALID_IMAGE,
                                    "image of " + std::to_string(height) + " rows of stride " +
                                        std::to_string(stride) + " bytes is larger than memory");
        }
        len = stride * (height - 1) + row;
    }
    return image_view(data, len, width, height, format, stride);
}

/// A borrowed depth image registered to a keyframe image (the C struct, ABI 1.15), for
/// `LoopDetector::add_image`: `values_len` = `width * height` of that image row-major 16-bit
/// values at `values`, `units_per_metre` of them per metre (1000 for millimetres, 5000 for TUM
/// RGB-D); a value of 0 is no depth at that pixel. Read only during the call it is passed to;
/// `values == nullptr` means no depth image. Make one with `depth_view`.
using DepthImage = topoloc_depth_image;

/// A view of `len` depth values at `values`, `units_per_metre` per metre (checked by the library
/// when the depth image is used: `len` must be the image's pixel count).
[[nodiscard]] inline DepthImage depth_view(const uint16_t *values, std::size_t len,
                                           double units_per_metre) noexcept
{
    DepthImage depth{};
    depth.values = values;
    depth.values_len = len;
    depth.units_per_metre = units_per_metre;
    return depth;
}

/// `depth_view` over a vector (borrowed: it must outlive the call the view is passed to).
[[nodiscard]] inline DepthImage depth_view(const std::vector<uint16_t> &values,
                                           double units_per_metre) noexcept
{
    return depth_view(values.data(), values.size(), units_per_metre);
}

/// A view of a temporary vector would dangle: keep the vector alive while its view is used.
DepthImage depth_view(std::vector<uint16_t> &&values, double units_per_metre) = delete;

} // namespace topoloc

#endif // TOPOLOC_IMAGE_HPP
