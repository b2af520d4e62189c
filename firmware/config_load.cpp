// Reading a configuration's text into ServiceConfig (config_load.h): TOML
// values converted to each field's type, unknown names with a suggestion, the
// origin of every value for validation's messages.
#include "firmware/config_load.h"

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <utility>
#include <variant>
#include <vector>

#include <toml.hpp>

#include "firmware/config_values.h"

namespace fovea::firmware::config_detail {

namespace {

const char* typeName(const toml::value& v) {
  switch (v.type()) {
    case toml::value_t::boolean: return "a boolean";
    case toml::value_t::integer: return "an integer";
    case toml::value_t::floating: return "a float";
    case toml::value_t::string: return "a string";
    case toml::value_t::array: return "an array";
    case toml::value_t::table: return "a table";
    case toml::value_t::empty: return "nothing";
    default: return "a date or time";
  }
}

const char* expectedName(Kind kind) {
  switch (kind) {
    case Kind::kBool: return "a boolean";
    case Kind::kInt: return "an integer";
    case Kind::kFloat: return "a number";
    case Kind::kString:
    case Kind::kChoice: return "a string";
    case Kind::kFloatList: return "an array of numbers";
  }
  return "?";
}

// The TOML value as the field's type, or the message why not.
std::variant<Value, std::string> convert(const Field& field, const toml::value& v) {
  const std::string wrong = std::string("expected ") + expectedName(field.kind) + ", got " + typeName(v);
  switch (field.kind) {
    case Kind::kBool:
      if (v.is_boolean()) return Value(v.as_boolean());
      return wrong;
    case Kind::kInt:
      if (v.is_integer()) return Value(static_cast<int64_t>(v.as_integer()));
      return wrong;
    case Kind::kFloat:
      if (v.is_floating()) return Value(static_cast<double>(v.as_floating()));
      if (v.is_integer()) return Value(static_cast<double>(v.as_integer()));
      return wrong;
    case Kind::kString:
    case Kind::kChoice:
      if (v.is_string()) return Value(v.as_string().str);
      return wrong;
    case Kind::kFloatList: {
      if (!v.is_array()) return wrong;
      std::vector<double> list;
      for (const toml::value& element : v.as_array()) {
        if (element.is_floating()) {
          list.push_back(element.as_floating());
        } else if (element.is_integer()) {
          list.push_back(static_cast<double>(element.as_integer()));
        } else {
          return std::string("expected an array of numbers, got an array holding ") + typeName(element);
        }
      }
      return Value(std::move(list));
    }
  }
  return wrong;
}

// Optimal string alignment distance (a transposition counts as one edit).
std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

// " (did you mean 'camera.spec'?)" for a near name, else "".
std::string suggestion(std::string_view name, bool section) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(2, name.size() / 4) + 1;
  auto consider = [&](std::string_view candidate) {
    // A name without its unit or suffix ("stream.budget") is one edit away.
    const bool prefix = candidate.size() > name.size() && candidate.substr(0, name.size()) == name &&
                        candidate[name.size()] == '_';
    const std::size_t distance = prefix ? 1 : editDistance(name, candidate);
    if (distance < best_distance) {
      best_distance = distance;
      best = candidate;
    }
  };
  if (section) {
    for (const std::string& s : sections()) consider(s);
  } else {
    for (const Field& field : fields()) consider(field.path);
  }
  return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}

// A field's value from a TOML value: type, range, then set.
Status assign(ServiceConfig& config, const Field& field, const toml::value& v, const std::string& where) {
  std::variant<Value, std::string> converted = convert(field, v);
  if (const std::string* error = std::get_if<std::string>(&converted)) {
    return invalidArgument(where + ": " + field.path + ": " + *error);
  }
  const Value& value = std::get<Value>(converted);
  if (std::string error = checkValue(field, value); !error.empty()) {
    return invalidArgument(where + ": " + field.path + ": " + error);
  }
  field.set(config, value);
  return Status::ok();
}

// The first line of a toml11 message, without its "[error] " tag.
std::string firstLine(std::string_view what) {
  std::string_view line = what.substr(0, what.find('\n'));
  if (line.rfind("[error] ", 0) == 0) line.remove_prefix(8);
  return std::string(line);
}

Result<toml::value> parseToml(const std::string& text, const std::string& name) {
  try {
    std::istringstream in(text);
    return toml::parse(in, name);
  } catch (const toml::syntax_error& e) {
    return Result<toml::value>(ErrorCode::kParseError, name + ":" + std::to_string(e.location().line()) +
                                                           ": syntax error: " + firstLine(e.what()));
  } catch (const std::exception& e) {
    return Result<toml::value>(ErrorCode::kParseError, name + ": " + firstLine(e.what()));
  }
}

struct Entry {
  std::size_t line = 0;
  std::string path;
  const toml::value* value = nullptr;
};

// Every key of a parsed file: fields as entries, unknown names and misplaced
// tables as errors (each at its line).
void collect(const toml::value& table, const std::string& prefix, std::vector<Entry>& entries,
             std::vector<std::pair<std::size_t, std::string>>& errors) {
  for (const auto& [key, value] : table.as_table()) {
    const std::string path = prefix.empty() ? key : prefix + "." + key;
    const std::size_t line = value.location().line();
    const Field* field = findField(path);
    if (value.is_table() && !field) {
      if (sections().count(path)) {
        collect(value, path, entries, errors);
      } else {
        errors.emplace_back(line, "unknown section '" + path + "'" + suggestion(path, true));
      }
    } else if (field) {
      entries.push_back({line, path, &value});
    } else if (sections().count(path)) {
      errors.emplace_back(line, path + ": expected a table (a [" + path + "] section), got " + typeName(value));
    } else {
      errors.emplace_back(line, "unknown key '" + path + "'" + suggestion(path, false));
    }
  }
}

}  // namespace

Result<std::string> readFile(const std::string& path) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) return Result<std::string>(ErrorCode::kNotFound, "cannot open '" + path + "': " + std::strerror(errno));
  std::string text;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, file)) > 0) text.append(buffer, n);
  const bool failed = std::ferror(file) != 0;
  const int error = errno;
  std::fclose(file);
  if (failed) return Result<std::string>(ErrorCode::kIoError, "cannot read '" + path + "': " + std::strerror(error));
  return text;
}

Status loadTextInto(const std::string& text, const std::string& path, ServiceConfig& config, Origins& origins) {
  Result<toml::value> root = parseToml(text, path);
  if (!root) return root.status();
  std::vector<Entry> entries;
  std::vector<std::pair<std::size_t, std::string>> errors;
  collect(root.value(), "", entries, errors);
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.line < b.line; });
  std::sort(errors.begin(), errors.end());
  const std::size_t first_error_line = errors.empty() ? SIZE_MAX : errors.front().first;
  for (const Entry& entry : entries) {
    if (entry.line > first_error_line) break;
    const std::string where = path + ":" + std::to_string(entry.line);
    if (Status s = assign(config, *findField(entry.path), *entry.value, where); !s) return s;
    origins[entry.path] = where;
  }
  if (!errors.empty()) {
    return invalidArgument(path + ":" + std::to_string(errors.front().first) + ": " + errors.front().second);
  }
  return Status::ok();
}

Status loadInto(const std::string& path, ServiceConfig& config, Origins& origins) {
  Result<std::string> text = readFile(path);
  if (!text) return text.status();
  return loadTextInto(text.value(), path, config, origins);
}

Status applyOverrideTracked(ServiceConfig& config, std::string_view assignment, Origins& origins) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string_view::npos || eq == 0) {
    return invalidArgument("--set: '" + std::string(assignment) + "' is not section.key=value");
  }
  std::string path(assignment.substr(0, eq));
  const std::string text(assignment.substr(eq + 1));
  const Field* field = findField(path);
  if (!field && path.find('.') != std::string::npos) {
    // A key short of its outer section, when only one key ends so
    // (pose.source = camera.pose.source): what the docs' prose says.
    const Field* only = nullptr;
    int matches = 0;
    for (const Field& f : fields()) {
      const std::string_view full = f.path;
      if (full.size() > path.size() && full.substr(full.size() - path.size()) == path &&
          full[full.size() - path.size() - 1] == '.') {
        only = &f;
        ++matches;
      }
    }
    if (matches == 1) {
      field = only;
      path = only->path;
    }
  }
  if (!field) {
    if (sections().count(path)) return invalidArgument("--set: '" + path + "' is a section; set one of its keys");
    return invalidArgument("--set: unknown key '" + path + "'" + suggestion(path, false));
  }
  const bool stringy = field->kind == Kind::kString || field->kind == Kind::kChoice;
  if (stringy && (text.empty() || (text.front() != '"' && text.front() != '\''))) {
    // Bare text for a string: camera.spec=mock:balloon.
    const toml::value value(text);
    if (Status s = assign(config, *field, value, "--set"); !s) return s;
  } else {
    Result<toml::value> root = parseToml("v = " + text + "\n", "--set");
    if (!root) return invalidArgument("--set: " + path + ": '" + text + "' is not a TOML value");
    if (Status s = assign(config, *field, root->as_table().at("v"), "--set"); !s) return s;
  }
  origins[path] = "--set";
  return Status::ok();
}

}  // namespace fovea::firmware::config_detail
