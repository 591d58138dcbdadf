// Tests of the status table of the C++ layer (include/topoloc/error.hpp), checked against the
// library at run time: a status's name and description come from the library
// (topoloc_status_name, topoloc_status_str), only its exception class from C++
// (topoloc::detail::error_class). Every code the library names has an exception class and every
// code with one is named by the library; each error status throws its class, carrying the code,
// its name and the message. (Every enumerator of topoloc.h has a class too: error_class's switch
// names them all, and -Wswitch -Werror, as tests/cpp/run.sh compiles, refuses one left out.)
// Built and run by tests/cpp/run.sh.

#include "topoloc.hpp"

#include "harness.hpp"

#include <typeindex>
#include <typeinfo>

namespace {

using topoloc::detail::ErrorClass;

// The codes swept: the library's codes lie in groups of a hundred below 1000 (topoloc.h); the
// sweep goes far beyond, so that a code out of those groups is seen too.
constexpr uint32_t kSweep = 1u << 16;

// The exception class of each `ErrorClass` that is thrown (by its exact type).
const std::pair<ErrorClass, std::type_index> kThrownAs[] = {
    {ErrorClass::Error, typeid(topoloc::Error)},
    {ErrorClass::InvalidImage, typeid(topoloc::InvalidImageError)},
    {ErrorClass::UninformativeImage, typeid(topoloc::UninformativeImageError)},
    {ErrorClass::BackendUnavailable, typeid(topoloc::BackendUnavailableError)},
    {ErrorClass::Model, typeid(topoloc::ModelError)},
    {ErrorClass::NoDescriber, typeid(topoloc::NoDescriberError)},
    {ErrorClass::Cancelled, typeid(topoloc::CancelledError)},
};

// The class of the exception `topoloc::throw_error(status, message)` throws (`Unmapped` for
// none at all, or one of another type, which would be a bug).
ErrorClass thrown_class(topoloc_status status, const std::string &message)
{
    try {
        topoloc::throw_error(status, message);
    } catch (const topoloc::Error &e) {
        for (const auto &[error_class, type] : kThrownAs) {
            if (std::type_index(typeid(e)) == type) {
                return error_class;
            }
        }
    } catch (...) {
    }
    return ErrorClass::Unmapped;
}

TEST(library_names_exactly_the_mapped_statuses)
{
    int named = 0;
    for (uint32_t code = 0; code < kSweep; ++code) {
        const auto status = static_cast<topoloc_status>(code);
        const char *name = topoloc_status_name(code);
        const ErrorClass mapped = topoloc::detail::error_class(status);
        if (name != nullptr && mapped == ErrorClass::Unmapped) {
            report_failure(__FILE__, __LINE__,
                           std::string(name) + " (" + std::to_string(code) +
                               ") has no exception class in topoloc/error.hpp");
        }
        if (name == nullptr && mapped != ErrorClass::Unmapped) {
            report_failure(__FILE__, __LINE__,
                           "code " + std::to_string(code) +
                               " has an exception class but the library does not name it");
        }
        if (name != nullptr) {
            ++named;
            // The C++ names and descriptions are the library's.
            CHECK(topoloc::status_name(status) == name);
            CHECK(std::string(topoloc::status_string(status)) == topoloc_status_str(code));
            CHECK(std::string(topoloc::status_string(status)) != "unknown status code");
        } else {
            CHECK(topoloc::status_name(status) == nullptr);
        }
    }
    std::printf("    %d status codes named by the library\n", named);
    CHECK(named >= 20); // fewer: the sweep or the library's table is broken
    CHECK(topoloc::detail::error_class(TOPOLOC_OK) == ErrorClass::None);
    CHECK(std::string(topoloc_status_name(0)) == "TOPOLOC_OK");
}

TEST(each_error_status_throws_its_class_with_code_name_and_message)
{
    for (uint32_t code = 1; code < kSweep; ++code) {
        const char *name = topoloc_status_name(code);
        if (name == nullptr) {
            continue;
        }
        const auto status = static_cast<topoloc_status>(code);
        const std::string marker = std::string("message of ") + name;
        const ErrorClass expected = topoloc::detail::error_class(status);
        const ErrorClass thrown = thrown_class(status, marker);
        if (thrown != expected) {
            report_failure(__FILE__, __LINE__,
                           std::string(name) + " is thrown as class " +
                               std::to_string(static_cast<int>(thrown)) + ", mapped to " +
                               std::to_string(static_cast<int>(expected)));
        }
        try {
            topoloc::throw_error(status, marker);
        } catch (const topoloc::Error &e) {
            const std::string what = e.what();
            const bool carries = e.status() == status && e.message() == marker &&
                                 what.find(topoloc_status_str(code)) == 0 &&
                                 what.find(std::string("[") + name + " = " + std::to_string(code) +
                                           "]: " + marker) != std::string::npos;
            if (!carries) {
                report_failure(__FILE__, __LINE__,
                               std::string(name) +
                                   ": the exception does not carry the code: " + what);
            }
        }
    }
}

TEST(a_code_the_library_does_not_name_is_a_plain_error)
{
    const uint32_t code = 4242u;
    CHECK(topoloc_status_name(code) == nullptr);
    const auto status = static_cast<topoloc_status>(code);
    CHECK(topoloc::detail::error_class(status) == ErrorClass::Unmapped);
    CHECK(thrown_class(status, "from the future") == ErrorClass::Error);
}

} // namespace

int main() { return run_all_tests(); }
