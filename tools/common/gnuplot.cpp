#include "tools/common/gnuplot.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>

namespace fovea::tools {

bool drawWithGnuplot(const std::string& dir, const std::string& script, const std::string& png) {
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0) {
    std::printf("gnuplot not found: no %s (install gnuplot-nox, then run 'gnuplot %s' in %s)\n", png.c_str(),
                script.c_str(), dir.c_str());
    return false;
  }
  // The directory in single quotes for the shell, its own quotes escaped.
  std::string quoted = "'";
  for (char ch : std::filesystem::absolute(dir).string()) quoted += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  quoted += "'";
  std::error_code ec;
  const std::filesystem::path out = std::filesystem::path(dir) / png;
  std::filesystem::remove(out, ec);
  const int rc = std::system(("cd " + quoted + " && gnuplot '" + script + "'").c_str());
  const bool drawn = rc == 0 && std::filesystem::exists(out, ec);
  if (!drawn) std::printf("gnuplot failed (status %d): no %s\n", rc, png.c_str());
  return drawn;
}

}  // namespace fovea::tools
