#include "tools/eval/csv_table.h"

#include <algorithm>
#include <fstream>
#include <sstream>

namespace fovea::tools {

int CsvTable::column(const std::string& name) const {
  const auto it = std::find(header.begin(), header.end(), name);
  return it == header.end() ? -1 : static_cast<int>(it - header.begin());
}

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::stringstream in(line);
  while (std::getline(in, field, ',')) out.push_back(field);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

Result<CsvTable> readCsvTable(const std::string& path, const std::vector<std::string>& required) {
  std::ifstream in(path);
  if (!in) return Result<CsvTable>(ErrorCode::kNotFound, path + ": cannot read");
  CsvTable csv;
  std::string line;
  if (!std::getline(in, line)) return Result<CsvTable>(ErrorCode::kParseError, path + ": empty");
  csv.header = splitCsvLine(line);
  for (const std::string& name : required) {
    if (csv.column(name) < 0) return Result<CsvTable>(ErrorCode::kParseError, path + ": no column '" + name + "'");
  }
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::vector<std::string> row = splitCsvLine(line);
    if (row.size() != csv.header.size()) break;
    csv.rows.push_back(std::move(row));
  }
  return csv;
}

}  // namespace fovea::tools
