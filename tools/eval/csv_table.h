// A CSV file read whole into a table of strings: the frame and timing logs the
// service and fovea-operator write (fovea-eval's results; bench/fovea-latency-report
// links fovea_eval_core for it).
#pragma once

#include <string>
#include <vector>

#include "core/result.h"

namespace fovea::tools {

struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  // The index of column `name`, -1 when there is none.
  int column(const std::string& name) const;
};

// The fields of one line, split at every comma (a trailing comma ends with an
// empty field). No quoting: the logs never quote.
std::vector<std::string> splitCsvLine(const std::string& line);

// Reads `path`: kNotFound when it cannot be read; kParseError when it is empty or
// lacks a `required` column (the message names the file and the column). Empty
// lines are skipped; a line with another number of fields than the header (cut
// short: the writer was stopped) ends the table.
Result<CsvTable> readCsvTable(const std::string& path, const std::vector<std::string>& required);

}  // namespace fovea::tools
