// The part every fuzz target shares (tests/fuzz/fuzz_target.h): the generated
// seeds for libFuzzer, or the driver main() for compilers without libFuzzer.
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tests/fuzz/fuzz_target.h"

#ifndef FOVEA_FUZZ_DRIVER

// Runs before libFuzzer reads its corpus folders, so seeds written into the
// first of them are part of the run.
extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  const char* dir = std::getenv("FOVEA_FUZZ_WRITE_SEEDS");
  if (dir == nullptr || *dir == '\0') return 0;
  const std::vector<fovea::fuzz::Input> seeds = fovea::fuzz::seeds();
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    const std::string path = std::string(dir) + "/generated-" + std::to_string(i);
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr || std::fwrite(seeds[i].data(), 1, seeds[i].size(), f) != seeds[i].size()) {
      std::fprintf(stderr, "fuzz: cannot write the seed %s\n", path.c_str());
      std::exit(2);
    }
    std::fclose(f);
  }
  return 0;
}

#else

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string_view>

namespace {

using fovea::fuzz::Input;

std::vector<Input> readFolder(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> paths;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file()) paths.push_back(entry.path());
  }
  std::sort(paths.begin(), paths.end());  // the same order on every machine
  std::vector<Input> inputs;
  for (const auto& path : paths) {
    std::ifstream in(path, std::ios::binary);
    inputs.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return inputs;
}

int hexDigit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// libFuzzer's dictionary format: one `name="token"` or `"token"` a line, with
// \\, \" and \xNN escapes; '#' starts a comment.
std::vector<Input> readDictionary(const std::string& path) {
  std::vector<Input> tokens;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t open = line.find('"');
    const std::size_t close = line.rfind('"');
    if (line.empty() || line[0] == '#' || open == std::string::npos || close <= open) continue;
    Input token;
    for (std::size_t i = open + 1; i < close; ++i) {
      if (line[i] == '\\' && i + 1 < close) {
        if (line[i + 1] == 'x' && i + 3 < close && hexDigit(line[i + 2]) >= 0 && hexDigit(line[i + 3]) >= 0) {
          token.push_back(static_cast<uint8_t>(hexDigit(line[i + 2]) * 16 + hexDigit(line[i + 3])));
          i += 3;
        } else {
          token.push_back(static_cast<uint8_t>(line[++i]));
        }
      } else {
        token.push_back(static_cast<uint8_t>(line[i]));
      }
    }
    if (!token.empty()) tokens.push_back(std::move(token));
  }
  return tokens;
}

// A few edits of the kinds libFuzzer makes: bytes changed, inserted, erased,
// copied; the input cut; a dictionary token written over or into it.
void mutate(Input& in, const std::vector<Input>& dict, std::mt19937_64& rng) {
  static constexpr uint8_t kInteresting[] = {0x00, 0x01, 0x7f, 0x80, 0xff, '0', '9', ' ', '\n', '-', '.', 'e'};
  const int edits = 1 + static_cast<int>(rng() % 8);
  for (int e = 0; e < edits; ++e) {
    const std::size_t at = in.empty() ? 0 : rng() % (in.size() + 1);
    switch (rng() % 8) {
      case 0:
        if (at < in.size()) in[at] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1:
        if (at < in.size()) in[at] = kInteresting[rng() % std::size(kInteresting)];
        break;
      case 2: in.insert(in.begin() + static_cast<std::ptrdiff_t>(at), static_cast<uint8_t>(rng())); break;
      case 3:
        if (at < in.size()) {
          const std::size_t n = std::min<std::size_t>(1 + rng() % 16, in.size() - at);
          in.erase(in.begin() + static_cast<std::ptrdiff_t>(at), in.begin() + static_cast<std::ptrdiff_t>(at + n));
        }
        break;
      case 4: in.resize(at); break;
      case 5:
        if (!in.empty()) {  // a copy of a range, inserted elsewhere
          const std::size_t from = rng() % in.size();
          const std::size_t n = std::min<std::size_t>(1 + rng() % 32, in.size() - from);
          const Input piece(in.begin() + static_cast<std::ptrdiff_t>(from),
                            in.begin() + static_cast<std::ptrdiff_t>(from + n));
          in.insert(in.begin() + static_cast<std::ptrdiff_t>(at), piece.begin(), piece.end());
        }
        break;
      default:
        if (!dict.empty()) {
          const Input& token = dict[rng() % dict.size()];
          if (rng() % 2 == 0) {
            in.insert(in.begin() + static_cast<std::ptrdiff_t>(at), token.begin(), token.end());
          } else {
            for (std::size_t i = 0; i < token.size(); ++i) {
              if (at + i < in.size()) in[at + i] = token[i]; else in.push_back(token[i]);
            }
          }
        }
        break;
    }
  }
}

}  // namespace

// NAME [ITERATIONS] [-dict=FILE] [CORPUS_DIR...]: the seeds (generated and
// from the folders) once each, then ITERATIONS inputs: mostly mutated seeds,
// one in eight random bytes. Seeded: every run makes the same inputs.
int main(int argc, char** argv) {
  long iterations = 10000;
  std::vector<Input> pool = fovea::fuzz::seeds();
  std::vector<Input> dict;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg.rfind("-dict=", 0) == 0) {
      dict = readDictionary(std::string(arg.substr(6)));
    } else if (!arg.empty() && arg.find_first_not_of("0123456789") == std::string_view::npos) {
      iterations = std::atol(argv[i]);
    } else if (std::filesystem::is_directory(arg)) {
      std::vector<Input> files = readFolder(arg);
      pool.insert(pool.end(), std::make_move_iterator(files.begin()), std::make_move_iterator(files.end()));
    } else {
      std::fprintf(stderr, "%s: '%s' is neither an iteration count, -dict=FILE nor a folder\n", argv[0], argv[i]);
      return 2;
    }
  }
  for (const Input& seed : pool) LLVMFuzzerTestOneInput(seed.data(), seed.size());
  std::mt19937_64 rng(1);
  Input input;
  for (long i = 0; i < iterations; ++i) {
    if (pool.empty() || i % 8 == 0) {
      input.resize(rng() % 512);
      for (uint8_t& b : input) b = static_cast<uint8_t>(rng());
    } else {
      input = pool[rng() % pool.size()];
      mutate(input, dict, rng);
    }
    LLVMFuzzerTestOneInput(input.data(), input.size());
  }
  std::printf("%s: %zu seeds and %ld generated inputs, no crash\n", argv[0], pool.size(), iterations);
  return 0;
}

#endif
