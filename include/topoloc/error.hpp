/*
 * topoloc/error.hpp: statuses and exceptions of the C++ layer (part of topoloc.hpp, which has the
 * overview). Every failing C call becomes a `topoloc::Error` (or a subclass) carrying the C
 * status and the thread-local message of `topoloc_last_error_message`.
 *
 * A status's name and description come from the library (`topoloc_status_name`,
 * `topoloc_status_str`); this header holds only what is C++'s own: the exception class each
 * status is thrown as (`detail::error_class`).
 */

#ifndef TOPOLOC_ERROR_HPP
#define TOPOLOC_ERROR_HPP

#include "../topoloc.h"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>

namespace topoloc {

/// Static English description of a status code (`topoloc_status_str`); never null, never freed.
[[nodiscard]] inline const char *status_string(topoloc_status status) noexcept
{
    return topoloc_status_str(static_cast<uint32_t>(status));
}

/// The C name of a status ("TOPOLOC_ERR_IO"; `topoloc_status_name`), or null for a code the
/// loaded library does not know. Never freed.
[[nodiscard]] inline const char *status_name(topoloc_status status) noexcept
{
    return topoloc_status_name(static_cast<uint32_t>(status));
}

namespace detail {

/// The exception class a status is thrown as (see `throw_error`).
enum class ErrorClass {
    Unmapped,           ///< A code this header does not know (from a newer library): `Error`.
    None,               ///< `TOPOLOC_OK`: nothing is thrown.
    Error,              ///< `topoloc::Error` itself.
    InvalidImage,       ///< `InvalidImageError`.
    UninformativeImage, ///< `UninformativeImageError`.
    BackendUnavailable, ///< `BackendUnavailableError`.
    Model,              ///< `ModelError`.
    NoDescriber,        ///< `NoDescriberError`.
    Cancelled,          ///< `CancelledError`.
};

/// The C++ part of the status table: the exception class of every `topoloc_status` of
/// topoloc.h. The switch names every enumerator and has no default, so a code added to
/// topoloc.h and not here is a -Wswitch warning (an error under -Werror); tests/cpp/test_status.cpp
/// walks every code the library names and checks that it is mapped here, and that every code
/// mapped here is one the library names.
constexpr ErrorClass error_class(topoloc_status status) noexcept
{
    switch (status) {
    case TOPOLOC_OK:
        return ErrorClass::None;
    case TOPOLOC_ERR_NULL_ARGUMENT:
    case TOPOLOC_ERR_INVALID_ARGUMENT:
    case TOPOLOC_ERR_BUFFER_TOO_SMALL:
    case TOPOLOC_ERR_STRUCT_SIZE:
    case TOPOLOC_ERR_INVALID_UTF8:
    case TOPOLOC_ERR_CONCURRENT_USE:
    case TOPOLOC_ERR_IO:
    case TOPOLOC_ERR_NOT_A_MAP:
    case TOPOLOC_ERR_TRUNCATED:
    case TOPOLOC_ERR_CORRUPT:
    case TOPOLOC_ERR_UNSUPPORTED_VERSION:
    case TOPOLOC_ERR_DESCRIPTOR_MISMATCH:
    case TOPOLOC_ERR_EMPTY_MAP:
    case TOPOLOC_ERR_INVALID_MAP:
    case TOPOLOC_ERR_UNKNOWN_PLACE:
    case TOPOLOC_ERR_UNKNOWN_VIEW:
    case TOPOLOC_ERR_DIMENSION_MISMATCH:
    case TOPOLOC_ERR_NON_FINITE:
    case TOPOLOC_ERR_ZERO_DESCRIPTOR:
    case TOPOLOC_ERR_TIMESTAMP:
    case TOPOLOC_ERR_INVALID_OPTION:
    case TOPOLOC_ERR_PANIC:
        return ErrorClass::Error;
    case TOPOLOC_ERR_INVALID_IMAGE:
        return ErrorClass::InvalidImage;
    case TOPOLOC_ERR_UNINFORMATIVE_IMAGE:
        return ErrorClass::UninformativeImage;
    case TOPOLOC_ERR_BACKEND_UNAVAILABLE:
        return ErrorClass::BackendUnavailable;
    case TOPOLOC_ERR_MODEL:
        return ErrorClass::Model;
    case TOPOLOC_ERR_NO_DESCRIBER:
        return ErrorClass::NoDescriber;
    case TOPOLOC_ERR_CANCELLED:
        return ErrorClass::Cancelled;
    }
    return ErrorClass::Unmapped;
}

} // namespace detail

/// The message of the most recent failed C call on the calling thread ("" if none).
/// Reads the size first and then the text, so messages of any length are returned whole.
/// Does not change the stored message. Never throws except `std::bad_alloc`.
[[nodiscard]] inline std::string last_error_message()
{
    std::size_t needed = 0;
    // First ask for the size: with an empty buffer the call reports BUFFER_TOO_SMALL and `needed`.
    topoloc_last_error_message(nullptr, 0, &needed);
    // The stored message cannot change between these calls (it is per thread and only failing
    // C calls on this thread replace it), but loop anyway rather than trust that.
    for (int attempt = 0; attempt < 4 && needed > 0; ++attempt) {
        std::string text(needed, '\0');
        std::size_t again = 0;
        const topoloc_status status = topoloc_last_error_message(&text[0], text.size(), &again);
        if (status == TOPOLOC_OK) {
            text.resize(std::strlen(text.c_str()));
            return text;
        }
        if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
            break;
        }
        needed = again;
    }
    return std::string();
}

/// Exception thrown by every wrapper call whose C call fails. `status()` is the C status code;
/// `message()` the library's message for it (from `topoloc_last_error_message`, or written by
/// this layer for errors it detects itself); `what()` is "<status description>: <message>".
class Error : public std::runtime_error {
public:
    /// An error with an explicit status and message (used for errors this layer detects).
    Error(topoloc_status status, std::string message)
        : std::runtime_error(compose(status, message)), status_(status),
          message_(std::move(message))
    {
    }

    /// The error of the C call that just failed on this thread with `status`: reads the
    /// thread-local message. Call it before any other topoloc call on this thread.
    [[nodiscard]] static Error from_last(topoloc_status status)
    {
        return Error(status, last_error_message());
    }

    /// The C status code (never `TOPOLOC_OK`).
    [[nodiscard]] topoloc_status status() const noexcept { return status_; }

    /// The message alone, without the status description ("" if the library gave none).
    [[nodiscard]] const std::string &message() const noexcept { return message_; }

private:
    // "<description> [<NAME> = <code>]: <message>", e.g.
    // "I/O error [TOPOLOC_ERR_IO = 100]: cannot open /x.topoloc: No such file or directory".
    static std::string compose(topoloc_status status, const std::string &message)
    {
        std::string text = status_string(status);
        text += " [";
        const char *name = status_name(status);
        text += name != nullptr ? name : "status";
        text += " = ";
        text += std::to_string(static_cast<uint32_t>(status));
        text += "]";
        if (!message.empty()) {
            text += ": ";
            text += message;
        }
        return text;
    }

    topoloc_status status_;
    std::string message_;
};

/// `TOPOLOC_ERR_INVALID_IMAGE`: an image buffer is unusable (size, stride, length, format), or
/// an image file cannot be read (the message names it).
class InvalidImageError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_UNINFORMATIVE_IMAGE`: the image carries no place information (blank, constant,
/// featureless). The frame was not localized and the localizer is unchanged: skip the frame.
class UninformativeImageError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_BACKEND_UNAVAILABLE`: ONNX Runtime or the model file is missing or cannot be
/// loaded; the message names every path tried.
class BackendUnavailableError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_MODEL`: the model file loaded but does not work.
class ModelError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_NO_DESCRIBER`: an image frame reached a localizer that cannot describe images
/// (a map built from descriptors, or `image_backend = TOPOLOC_BACKEND_NONE`).
class NoDescriberError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_CANCELLED`: the progress callback returned false.
class CancelledError : public Error {
public:
    using Error::Error;
};

/// Throws the exception class of `status` (`detail::error_class`) with `message`: a subclass of
/// `Error` for the image statuses, `Error` itself for every other status, including codes newer
/// than this header. `status` must not be `TOPOLOC_OK` (it is thrown as `Error` too, which is a
/// caller's bug).
[[noreturn]] inline void throw_error(topoloc_status status, std::string message)
{
    switch (detail::error_class(status)) {
    case detail::ErrorClass::InvalidImage:
        throw InvalidImageError(status, std::move(message));
    case detail::ErrorClass::UninformativeImage:
        throw UninformativeImageError(status, std::move(message));
    case detail::ErrorClass::BackendUnavailable:
        throw BackendUnavailableError(status, std::move(message));
    case detail::ErrorClass::Model:
        throw ModelError(status, std::move(message));
    case detail::ErrorClass::NoDescriber:
        throw NoDescriberError(status, std::move(message));
    case detail::ErrorClass::Cancelled:
        throw CancelledError(status, std::move(message));
    case detail::ErrorClass::Unmapped:
    case detail::ErrorClass::None:
    case detail::ErrorClass::Error:
        break;
    }
    throw Error(status, std::move(message));
}

/// Throws (see `throw_error`) with the thread's last error message unless `status` is
/// `TOPOLOC_OK`. Use it right after a C call, before any other topoloc call on this thread.
inline void check(topoloc_status status)
{
    if (status != TOPOLOC_OK) {
        throw_error(status, last_error_message());
    }
}

} // namespace topoloc

#endif // TOPOLOC_ERROR_HPP
