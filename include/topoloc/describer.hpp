/*
 * topoloc/describer.hpp: `Describer`, a map's describer on its own, which turns images into
 * global descriptors (ABI 1.12; part of topoloc.hpp, which has the overview; its options are in
 * options.hpp).
 */

#ifndef TOPOLOC_DESCRIBER_HPP
#define TOPOLOC_DESCRIBER_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "image.hpp"
#include "map.hpp"

#include <cstddef>
#include <vector>

namespace topoloc {

/// Owner of a describer (`topoloc_describer*`, ABI 1.12): a map's describer on its own, which
/// turns images into global descriptors exactly as the map's views were described, e.g. for
/// `LoopKeyframe::descriptor` or `Frame::descriptor`. Move-only; the destructor calls
/// `topoloc_describer_free`; it does not keep the map.
///
/// Thread safety: single-threaded state; use from one thread at a time (it may move between
/// threads); one describer per thread for parallel work.
/// Errors: every method that calls the library throws `Error` (or its status subclass); a
/// failed `describe` leaves the output untouched.
class Describer : public detail::Owner<topoloc_describer, &topoloc_describer_free> {
public:
    /// An empty owner (`!describer`).
    Describer() noexcept = default;

    /// Loads `map`'s describer (for ONNX: the runtime and the model, checked by hash). Throws
    /// `NoDescriberError` (a map built from descriptors), `BackendUnavailableError` (paths tried
    /// in the message), `ModelError`, `Error` (`TOPOLOC_ERR_DESCRIPTOR_MISMATCH` for another
    /// backend or model than the map's, `_INVALID_OPTION`, `_STRUCT_SIZE`, `_NULL_ARGUMENT` for
    /// an empty map).
    explicit Describer(const Map &map,
                       const DescriberOptions &options = default_describer_options())
    {
        topoloc_describer *raw = nullptr;
        check(topoloc_describer_new(map.capi(), &options, &raw));
        adopt(raw);
        dim_ = read_value(&topoloc_describer_dim);
    }

    /// The descriptor dimension D (the map's).
    [[nodiscard]] std::size_t dim() const noexcept { return dim_; }

    /// Describes `image` into `out` (resized to D; its storage is reused from call to call).
    /// Throws `InvalidImageError` (also for no image), `UninformativeImageError` (no content),
    /// `ModelError`, `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    void describe(const Image &image, std::vector<float> &out)
    {
        std::vector<float> next(dim_);
        check(topoloc_describer_describe(get(), &image, next.data(), next.size(), nullptr));
        out.swap(next);
    }

    /// Describes `image`: D floats of unit norm. Same errors as the other overload.
    [[nodiscard]] std::vector<float> describe(const Image &image)
    {
        std::vector<float> out;
        describe(image, out);
        return out;
    }

private:
    std::size_t dim_ = 0;
};

} // namespace topoloc

#endif // TOPOLOC_DESCRIBER_HPP
