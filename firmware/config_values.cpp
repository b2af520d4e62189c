// A configuration field's value checked (range, choices, UTF-8 text) and
// printed as TOML that loads back to the same value (config_values.h).
#include "firmware/config_values.h"

#include <algorithm>
#include <charconv>
#include <cstdio>

namespace fovea::firmware::config_detail {

namespace {

// As a TOML float: "100" would read back as an integer.
std::string formatFloat(double v) {
  std::string text = formatNumber(v);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

// What is wrong with a string value's bytes ("" when nothing). A TOML file is
// UTF-8, so formatServiceConfig could not print anything else loadably (--set's
// bare text is not parsed as TOML, so it can carry any bytes: fuzz_config found
// it); a control character (a NUL cuts a path short) is always a mistake here.
std::string checkText(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 || c == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", c);
      return "must not contain control characters (byte " + std::to_string(i) + " is " + hex + ")";
    }
    // RFC 3629: the length from the lead byte, continuation bytes 10xxxxxx, no
    // overlong forms, no surrogates, nothing above U+10FFFF.
    std::size_t length = 1;
    unsigned char lo = 0x80, hi = 0xbf;  // the range of the second byte
    if (c >= 0xc2 && c <= 0xdf) {
      length = 2;
    } else if (c >= 0xe0 && c <= 0xef) {
      length = 3;
      if (c == 0xe0) lo = 0xa0;
      if (c == 0xed) hi = 0x9f;
    } else if (c >= 0xf0 && c <= 0xf4) {
      length = 4;
      if (c == 0xf0) lo = 0x90;
      if (c == 0xf4) hi = 0x8f;
    } else if (c >= 0x80) {
      return "must be UTF-8 text (byte " + std::to_string(i) + " is not)";
    }
    for (std::size_t k = 1; k < length; ++k) {
      const auto b = i + k < text.size() ? static_cast<unsigned char>(text[i + k]) : 0;
      if (b < (k == 1 ? lo : 0x80) || b > (k == 1 ? hi : 0xbf)) {
        return "must be UTF-8 text (byte " + std::to_string(i) + " is not)";
      }
    }
    i += length;
  }
  return "";
}

}  // namespace

std::string formatNumber(double v) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, v);
  return std::string(buffer, result.ptr);
}

std::string quote(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20 || c == 0x7f) {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\u%04x", c);
      out += escaped;
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

std::string formatValue(const Value& value) {
  if (const bool* b = std::get_if<bool>(&value)) return *b ? "true" : "false";
  if (const int64_t* i = std::get_if<int64_t>(&value)) return std::to_string(*i);
  if (const double* d = std::get_if<double>(&value)) return formatFloat(*d);
  if (const std::string* s = std::get_if<std::string>(&value)) return quote(*s);
  std::string out = "[";
  for (const double d : std::get<std::vector<double>>(value)) {
    if (out.size() > 1) out += ", ";
    out += formatFloat(d);
  }
  return out + "]";
}

std::string checkValue(const Field& field, const Value& value) {
  auto outside = [&field](double v) { return !(v >= field.min && v <= field.max); };
  auto bound = [&field](double v) {
    return field.kind == Kind::kInt ? std::to_string(static_cast<int64_t>(v)) : formatNumber(v);
  };
  auto range = [&](const std::string& got) {
    return "must be within " + bound(field.min) + " .. " + bound(field.max) + " (got " + got + ")";
  };
  switch (field.kind) {
    case Kind::kBool: return "";
    case Kind::kInt: {
      const int64_t v = std::get<int64_t>(value);
      return outside(static_cast<double>(v)) ? range(std::to_string(v)) : "";
    }
    case Kind::kFloat: {
      const double v = std::get<double>(value);
      return outside(v) ? range(formatNumber(v)) : "";
    }
    case Kind::kString: {
      const std::string& v = std::get<std::string>(value);
      if (std::string error = checkText(v); !error.empty()) return error;
      return field.check ? field.check(v) : "";
    }
    case Kind::kChoice: {
      const std::string& v = std::get<std::string>(value);
      if (std::string error = checkText(v); !error.empty()) return error;
      if (std::find(field.choices.begin(), field.choices.end(), v) != field.choices.end()) return "";
      std::string list;
      for (const std::string& choice : field.choices) list += (list.empty() ? "" : ", ") + quote(choice);
      return "must be one of " + list + " (got " + quote(v) + ")";
    }
    case Kind::kFloatList:
      for (const double v : std::get<std::vector<double>>(value)) {
        if (outside(v)) return "each must be within " + formatNumber(field.min) + " .. " + formatNumber(field.max) +
                               " (got " + formatNumber(v) + ")";
      }
      return "";
  }
  return "";
}

}  // namespace fovea::firmware::config_detail
