// fmt's implementation, compiled into MachineTwin.so.
//
// The twin's libraries are compiled against fmt as a library (not
// header-only) and the FMU links their objects, but not libfmt.so: the binary
// stays self-contained (docs/fmu.md). Those objects leave one fmt function
// undefined, fmt::vformat; format-inl.h defines it with fmt's other
// non-template functions. The two templates below are what that code calls
// and format.h declares `extern template` (so nothing instantiates them
// implicitly); the link with --no-undefined names any that goes missing.
#include <fmt/format-inl.h>

FMT_BEGIN_NAMESPACE
namespace detail {

template auto thousands_sep_impl<char>(locale_ref) -> thousands_sep_result<char>;
template auto decimal_point_impl<char>(locale_ref) -> char;

}  // namespace detail
FMT_END_NAMESPACE
