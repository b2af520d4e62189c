// What every fuzz target in tests/fuzz/ defines, and what fuzz_support.cpp
// gives them (tests/fuzz/README.md).
//
// A target defines LLVMFuzzerTestOneInput (any bytes: return 0, never crash,
// hang or throw) and fovea::fuzz::seeds(): valid inputs built in code with the
// real encoders (binary formats a text file in the corpus cannot hold well),
// empty when the committed corpus tests/fuzz/corpus/<name>/ is enough.
//
// Under clang the target is a libFuzzer binary; fuzz_support.cpp then writes
// seeds() as files into $FOVEA_FUZZ_WRITE_SEEDS (a corpus folder) before
// libFuzzer reads its corpus. With other compilers (FOVEA_FUZZ_DRIVER) it
// provides main(): a deterministic driver that runs the seeds, then mutations
// of them (with the dictionary's tokens) and random bytes, for a bounded number
// of iterations, so CTest runs every target with any compiler.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size);

namespace fovea::fuzz {

using Input = std::vector<uint8_t>;

std::vector<Input> seeds();

}  // namespace fovea::fuzz
