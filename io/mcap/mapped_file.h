// A file mapped read-only into memory, for the Reader (io/mcap/reader.h) over
// recordings larger than one would read into the heap (raw frames: gigabytes).
// Pages come in as the reader reaches them and leave under memory pressure.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/result.h"

namespace fovea::mcap {

class MappedFile {
 public:
  // kNotFound for a missing file, kInvalidInput for an empty one, kIoError otherwise;
  // each names the path.
  static Result<MappedFile> open(const std::string& path);
  MappedFile() = default;
  ~MappedFile();
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  std::span<const uint8_t> bytes() const { return {data_, size_}; }

 private:
  const uint8_t* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace fovea::mcap
