/*
 * topoloc/detail.hpp: how the C++ layer talks to the C ABI (internal; part of topoloc.hpp,
 * which has the overview): the one owner template of every C handle, versioned structs filled
 * by the library, and the size-then-read contract of strings and arrays.
 */

#ifndef TOPOLOC_DETAIL_HPP
#define TOPOLOC_DETAIL_HPP

#include "../topoloc.h"
#include "error.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace topoloc {
namespace detail {

/// The one move-only owner of a C handle, shared by every owner class of this layer (`Map`,
/// `MapBuilder`, `Localizer`, `Graph`, `Describer`, `KeyframeDescriber`, `LoopDetector` derive
/// from it): it holds a `Handle *`, calls `Free` (the handle's C `_free` function, a no-op for
/// null) when destroyed or assigned over, hands the handle out for interop (`capi()`, `get()`)
/// or gives it up (`release()`), and cannot be copied. Moved-from owners are empty. Not
/// thread-safe by itself; the derived classes state their own rules.
template <typename Handle, void (*Free)(Handle *)> class Owner {
public:
    /// The C handle type.
    using handle_type = Handle;

    /// The raw handle, still owned by this object (null when empty).
    [[nodiscard]] const Handle *capi() const noexcept { return handle_; }
    /// The raw handle, still owned by this object (null when empty).
    [[nodiscard]] Handle *capi() noexcept { return handle_; }
    /// Same as `capi()`.
    [[nodiscard]] const Handle *get() const noexcept { return handle_; }
    /// Same as `capi()`.
    [[nodiscard]] Handle *get() noexcept { return handle_; }

    /// Gives up ownership: returns the handle (free it with the C `_free` function) and leaves
    /// this object empty.
    [[nodiscard]] Handle *release() noexcept
    {
        Handle *raw = handle_;
        handle_ = nullptr;
        return raw;
    }

    /// True when this object owns a handle.
    explicit operator bool() const noexcept { return handle_ != nullptr; }

protected:
    Owner() noexcept = default;
    /// Takes ownership of `raw` (null gives an empty owner).
    explicit Owner(Handle *raw) noexcept : handle_(raw) {}
    Owner(const Owner &) = delete;
    Owner &operator=(const Owner &) = delete;
    Owner(Owner &&other) noexcept : handle_(other.release()) {}
    Owner &operator=(Owner &&other) noexcept
    {
        if (this != &other) {
            adopt(other.release());
        }
        return *this;
    }
    ~Owner() { Free(handle_); }

    /// Frees the current handle (if any) and owns `raw` instead.
    void adopt(Handle *raw) noexcept
    {
        Handle *old = handle_;
        handle_ = raw;
        Free(old);
    }

    /// The value a C getter `call(handle, &value)` writes (a count, a dimension).
    template <typename T>
    [[nodiscard]] T read_value(topoloc_status (*call)(const Handle *, T *)) const
    {
        T value{};
        check(call(handle_, &value));
        return value;
    }

    /// Edge `index` of a graph (a map's, a skeleton's) through its C getter
    /// `call(handle, index, &a, &b, &value)`: an `Edge` with members `a`, `b` and `value`.
    template <typename Edge, typename Value>
    [[nodiscard]] Edge read_edge(topoloc_status (*call)(const Handle *, std::size_t, uint32_t *,
                                                        uint32_t *, Value *),
                                 std::size_t index, Value Edge::*value) const
    {
        Edge edge;
        check(call(handle_, index, &edge.a, &edge.b, &(edge.*value)));
        return edge;
    }

private:
    Handle *handle_ = nullptr;
};

/// A versioned C struct (options, frames, results, records) as the library fills it: `init` is
/// its `topoloc_*_init` function, called with `sizeof` the struct as the header's
/// `topoloc_*_default(p)` macros do, so the library fills exactly the layout this program was
/// compiled with. It fails only when the library refuses that size (a header older than the
/// library's first published layout): `Error` with `TOPOLOC_ERR_STRUCT_SIZE`.
template <typename Struct>
[[nodiscard]] Struct filled(topoloc_status (*init)(Struct *, std::size_t))
{
    Struct value;
    check(init(&value, sizeof value));
    return value;
}

/// Optional string argument: "" becomes NULL (the C API treats both as "not given").
inline const char *optional_c_str(const std::string &s) noexcept
{
    return s.empty() ? nullptr : s.c_str();
}

/// Reads a string through a C function of the (buf, len, &needed) contract.
template <typename Call> std::string read_string(Call call)
{
    std::string text(64, '\0');
    for (int attempt = 0; attempt < 4; ++attempt) {
        std::size_t needed = 0;
        const topoloc_status status = call(&text[0], text.size(), &needed);
        if (status == TOPOLOC_OK) {
            text.resize(std::strlen(text.c_str())); // C strings hold no interior NUL
            return text;
        }
        if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
            check(status);
        }
        text.assign(needed, '\0');
    }
    throw Error(TOPOLOC_ERR_BUFFER_TOO_SMALL, "string kept growing while being read");
}

/// Reads an array through a C function of the (buf, len, &count) contract whose `count` items
/// are `per_item` values of `T` each (`len` counts values): returns the `count * per_item`
/// values.
template <typename T, typename Call> std::vector<T> read_array(Call call, std::size_t per_item = 1)
{
    std::vector<T> values;
    std::size_t count = 0;
    topoloc_status status = call(nullptr, 0, &count);
    if (status == TOPOLOC_OK) {
        return values; // empty
    }
    if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
        check(status);
    }
    values.resize(count * per_item);
    check(call(values.data(), values.size(), &count));
    values.resize(count * per_item);
    return values;
}

/// Items 0 .. `count` - 1 of a by-index getter `get(i)`, in order (all edges, all places).
template <typename T, typename Get> std::vector<T> read_all(std::size_t count, Get get)
{
    std::vector<T> all(count);
    for (std::size_t i = 0; i < count; ++i) {
        all[i] = get(i);
    }
    return all;
}

/// Reads an id array through a C function of the (buf, len, &count) contract.
template <typename Call> std::vector<uint32_t> read_ids(Call call)
{
    return read_array<uint32_t>(call);
}

} // namespace detail
} // namespace topoloc

#endif // TOPOLOC_DETAIL_HPP
