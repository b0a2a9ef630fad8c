// Append-only writer of one recording CSV (docs/guide/recording.md) for the live recorder: the
// header at open, then rows as they arrive. Each flush is one write() of whole rows, and a failed
// or short write is cut back to the last whole row, so a killed process leaves a file that ends on
// a row boundary and whatever reached the file replays.
#pragma once

#include <cstdint>
#include <string>

#include "agv/recording/recording.hpp"

namespace agv::recording {

// One row of each file, exactly as write_*_csv writes it (newline included).
bool format_frame_row(const FrameRow& row, std::string* text, std::string* error);
std::string format_odom_row(const OdomRow& row);
std::string format_imu_row(const ImuRow& row);
// The header line of each file (newline included).
std::string frames_csv_header();
std::string odom_csv_header();
std::string imu_csv_header();

class CsvStream {
 public:
  CsvStream() = default;
  ~CsvStream();  // close() without reporting
  CsvStream(const CsvStream&) = delete;
  CsvStream& operator=(const CsvStream&) = delete;

  // Creates `path` (never an existing file: a recording is not overwritten) and writes `header`
  // to it at once, so even a recording killed before its first row has a valid, empty file.
  bool open(const std::string& path, const std::string& header, std::string* error);
  bool is_open() const { return fd_ >= 0; }
  // Buffers one formatted row; it reaches the file at the next flush().
  void add(const std::string& row);
  // Writes the buffered rows. On failure the file is cut back to the rows written before, the
  // buffered rows are dropped (counted in rows_lost) and *error says why.
  bool flush(std::string* error);
  // fdatasync: what has been flushed survives a power loss.
  bool sync(std::string* error);
  // flush() + sync() + close. Idempotent.
  bool close(std::string* error);

  std::uint64_t rows_written() const { return rows_written_; }
  std::uint64_t rows_pending() const { return rows_pending_; }
  std::uint64_t rows_lost() const { return rows_lost_; }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
  std::string buffer_;
  std::uint64_t size_bytes_ = 0;  // whole rows on disk
  std::uint64_t rows_written_ = 0;
  std::uint64_t rows_pending_ = 0;
  std::uint64_t rows_lost_ = 0;
};

}  // namespace agv::recording
