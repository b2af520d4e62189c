// Drawing a report's PNG with gnuplot, when it is installed (the report tools
// write their .gp scripts either way, so that it can be drawn later).
#pragma once

#include <string>

namespace fovea::tools {

// Runs `gnuplot script` in dir and checks that it made `png` there (an older
// copy is removed first). False, with a line on stdout that says why (not
// installed, or gnuplot failed), when there is no PNG.
bool drawWithGnuplot(const std::string& dir, const std::string& script, const std::string& png);

}  // namespace fovea::tools
