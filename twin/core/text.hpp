#pragma once
/// Quoting user text in one-line error messages, and small words for notes.
#include <cstddef>
#include <string>
#include <string_view>

#include <fmt/format.h>

namespace twin {

/// Which bytes an excerpt shows as they are.
enum class ExcerptBytes {
  kAscii,    ///< printable ASCII only (G-code: anything else is a typing error)
  kUtf8Ok,   ///< printable ASCII and bytes >= 0x80 (YAML text may be UTF-8)
};

/// A printable excerpt of `text`: control bytes, backslashes and (kAscii)
/// bytes >= 0x7f as \xNN, cut after `max_chars` characters with "...", so a
/// 1 MB line gives a one-line message.
inline std::string printable_excerpt(std::string_view text, std::size_t max_chars, ExcerptBytes shown_bytes) {
  constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  std::size_t shown = 0;
  for (char ch : text) {
    if (shown == max_chars) {
      out += "...";
      break;
    }
    const auto c = static_cast<unsigned char>(ch);
    const bool high_ok = shown_bytes == ExcerptBytes::kUtf8Ok && c > 0x7f;
    if ((c >= 0x20 && c < 0x7f && c != '\\') || high_ok) {
      out.push_back(ch);
    } else {
      out += "\\x";
      out.push_back(kHex[c >> 4]);
      out.push_back(kHex[c & 0xf]);
    }
    ++shown;
  }
  return out;
}

/// "2nd", "3rd", "4th", ... for 2 to 20 (the rows of a loop period in notes).
inline std::string ordinal(std::size_t k) { return fmt::format("{}{}", k, k == 2 ? "nd" : k == 3 ? "rd" : "th"); }

}  // namespace twin
