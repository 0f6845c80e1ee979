#pragma once
/// \file The per-epoch training log (docs/formats.md): CSV with header
/// `epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds`.
///
/// - batch_loss: mean over the epoch's mini-batches of the loss before each update;
/// - train_loss / test_loss: the whole train / test set evaluated after the epoch; empty in an
///   epoch without evaluation (see `RunSettings::evaluate_every`) and test_loss empty without
///   a test set;
/// - update_norm2: mean over mini-batches of ‖vector fed to the optimizer‖² before clipping
///   (the reference's "update size");
/// - cos_m_r, agree_fraction: mean over mini-batches of cos(g_M, g_R) and of the share of
///   components whose signs agree; only the combined method computes both vectors, so the
///   fields are empty for the other methods;
/// - seconds: wall time of the epoch's updates (forward, sweeps, optimizer), without the
///   evaluation, as the reference logs it.
///
/// `TrainingLogFile` appends one row per epoch to the file (never rewrites it): the cost of a
/// run's log is linear in its epochs.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/number_text.hpp"

namespace sbptt {

/// One row of the training log.
struct EpochRecord {
  long epoch = 0;
  double batch_loss = 0;
  std::optional<double> train_loss;  ///< empty when the epoch was not evaluated
  std::optional<double> test_loss;   ///< empty when not evaluated or without a test set
  double update_norm2 = 0;
  std::optional<double> cos_m_r;
  std::optional<double> agree_fraction;
  double seconds = 0;
};

/// The log's header line, without the newline.
inline constexpr const char* training_log_header =
    "epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds";

/// One CSV row of the log, with its newline: the epoch, then %.17g, %.17g, %.17g, %.9g, %.9g,
/// %.9g and %.6f as printf writes them in the "C" locale, whatever the process's locale (a
/// decimal comma would break the CSV).
[[nodiscard]] inline std::string training_log_row(const EpochRecord& r) {
  using detail::append_formatted;
  constexpr auto general = std::chars_format::general;
  std::string line = std::to_string(r.epoch);
  auto field = [&](const std::optional<double>& v, int digits) {
    line += ',';
    if (v) append_formatted(line, *v, general, digits);
  };
  field(r.batch_loss, 17);
  field(r.train_loss, 17);
  field(r.test_loss, 17);
  field(r.update_norm2, 9);
  field(r.cos_m_r, 9);
  field(r.agree_fraction, 9);
  line += ',';
  append_formatted(line, r.seconds, std::chars_format::fixed, 6);
  line += '\n';
  return line;
}

/// The rows of a run in memory; `save` writes them all atomically.
class TrainingLog {
public:
  static constexpr const char* header = training_log_header;

  void add(const EpochRecord& record) { rows_.push_back(record); }
  [[nodiscard]] const std::vector<EpochRecord>& rows() const { return rows_; }

  [[nodiscard]] std::string csv() const {
    std::string text = std::string(header) + "\n";
    for (const auto& r : rows_) text += training_log_row(r);
    return text;
  }

  void save(const std::string& path) const { write_file_atomically(path, csv()); }

private:
  std::vector<EpochRecord> rows_;
};

/// The log as a file that grows by one appended row per epoch. A symbolic link at the path
/// is followed (its target grows). Counts what it writes (`bytes_written`, `writes`) so that
/// the linear cost can be checked.
class TrainingLogFile {
public:
  /// Starts a new log at `path`: the header is written atomically and durably (replacing any
  /// old file), then rows are appended. Throws `IoError` naming the path and the reason.
  static TrainingLogFile create(const std::string& path) {
    const std::string header_line = std::string(training_log_header) + "\n";
    write_file_atomically(path, header_line);
    TrainingLogFile log(path);
    log.size_ = static_cast<long long>(header_line.size());
    log.bytes_written_ = log.size_;
    log.writes_ = 1;
    return log;
  }

  /// Continues the log at `path` from its first `size` bytes (the size recorded with a
  /// checkpoint), which must hold the header and the rows of epochs 1 … `rows`: later rows,
  /// written after that checkpoint, are cut off. Throws `IoError` when the file is missing,
  /// does not start with the header, is shorter than `size`, or its first `size` bytes are not
  /// those rows, whole (a checkpoint or a log edited by hand, or the log of another run).
  static TrainingLogFile resume(const std::string& path, long long size, long rows) {
    TrainingLogFile log = open_for_resume(path, size, rows);
    log.cut_back();
    return log;
  }

  /// `resume` without its last step: the log checked, nothing cut yet, so that a caller can
  /// check the rest of a checkpoint before the log changes. Call `cut_back` before appending.
  static TrainingLogFile open_for_resume(const std::string& path, long long size, long rows) {
    TrainingLogFile log(path);
    struct stat info {};
    detail::require<IoError>(::fstat(log.fd_, &info) == 0 && info.st_size >= size,
                             "training log '", path, "' has ", info.st_size,
                             " bytes; the checkpoint expects at least ", size,
                             " (the log was cut or replaced)");
    const std::string header_line = std::string(training_log_header) + "\n";
    std::string start(header_line.size(), '\0');
    const ::ssize_t got = ::pread(log.fd_, start.data(), start.size(), 0);
    detail::require<IoError>(got == static_cast<::ssize_t>(start.size()) && start == header_line,
                             "training log '", path, "' does not start with the header '",
                             training_log_header, "'");
    log.require_rows(size, rows);
    log.size_ = size;
    return log;
  }

  /// Cuts off the rows after the size `open_for_resume` checked.
  void cut_back() {
    const bool cut = ::ftruncate(fd_, size_) == 0;  // before errno is read
    detail::require<IoError>(cut, "cannot cut training log '", path_, "' back to ", size_,
                             " bytes: ", detail::os_reason(errno));
  }

  TrainingLogFile(TrainingLogFile&& other) noexcept
      : path_(std::move(other.path_)), fd_(std::exchange(other.fd_, -1)), size_(other.size_),
        bytes_written_(other.bytes_written_), writes_(other.writes_) {}
  TrainingLogFile& operator=(TrainingLogFile&& other) noexcept {
    std::swap(path_, other.path_);
    std::swap(fd_, other.fd_);
    size_ = other.size_;
    bytes_written_ = other.bytes_written_;
    writes_ = other.writes_;
    return *this;
  }
  TrainingLogFile(const TrainingLogFile&) = delete;
  TrainingLogFile& operator=(const TrainingLogFile&) = delete;
  ~TrainingLogFile() {
    if (fd_ >= 0) ::close(fd_);
  }

  /// Appends the row of `record` with one write. Throws `IoError` (e.g. disk full, or the log
  /// replaced: `keep_in_place`).
  void append(const EpochRecord& record) {
    keep_in_place();
    const std::string row = training_log_row(record);
    const int error = detail::write_all(fd_, row);
    if (error != 0) {
      // A full disk takes part of the row: cut it off, so that the log stays whole rows.
      const int cut_error = ::ftruncate(fd_, size_) == 0 ? 0 : errno;
      throw IoError(detail::concat(
          "writing training log '", path_, "' failed: ", detail::os_reason(error),
          cut_error == 0 ? std::string("; the log keeps its whole rows")
                         : detail::concat("; cutting off the part written failed too: ",
                                          detail::os_reason(cut_error))));
    }
    size_ += static_cast<long long>(row.size());
    bytes_written_ += static_cast<long long>(row.size());
    ++writes_;
  }

  /// Makes every appended row durable (before a checkpoint records `size()`).
  void sync() {
    const bool synced = ::fsync(fd_) == 0;  // before errno is read
    detail::require<IoError>(synced, "cannot sync training log '", path_, "': ",
                             detail::os_reason(errno));
  }

  [[nodiscard]] long long size() const { return size_; }
  [[nodiscard]] long long bytes_written() const { return bytes_written_; }
  [[nodiscard]] long long writes() const { return writes_; }
  [[nodiscard]] const std::string& path() const { return path_; }

private:
  /// Puts the log back at its path when it was removed or renamed away during the run: its
  /// rows live on in the open file, but the checkpoints name the path, and a resume would
  /// find no log there. Throws `IoError` when another file has taken the path, or the open
  /// file no longer holds exactly what this log wrote: another writer's work, not to be
  /// overwritten.
  void keep_in_place() {
    struct stat open_file {}, at_path {};
    detail::require<IoError>(::fstat(fd_, &open_file) == 0 && open_file.st_size == size_,
                             "training log '", path_, "' was changed by another writer during "
                             "the run (it has ", open_file.st_size, " bytes where this run "
                             "wrote ", size_, "); expected it left to this run");
    if (::stat(path_.c_str(), &at_path) == 0) {
      detail::require<IoError>(at_path.st_dev == open_file.st_dev &&
                                   at_path.st_ino == open_file.st_ino,
                               "training log '", path_, "' was replaced by another file during "
                               "the run, which is left as it is; expected the log left to this "
                               "run");
      return;
    }
    if (errno != ENOENT) return;  // the path cannot be looked at: the write will say why
    std::string rows(static_cast<std::size_t>(size_), '\0');
    const ::ssize_t got = ::pread(fd_, rows.data(), rows.size(), 0);
    detail::require<IoError>(got == static_cast<::ssize_t>(rows.size()), "training log '",
                             path_, "' was removed during the run, and reading its rows back "
                             "failed: ", got < 0 ? detail::os_reason(errno) : "it is shorter");
    write_file_atomically(path_, rows);
    TrainingLogFile restored(path_);
    std::swap(fd_, restored.fd_);
  }

  /// The file's first `size` bytes are the header and whole rows numbered 1 … `rows`.
  void require_rows(long long size, long rows) const {
    std::string text(static_cast<std::size_t>(size), '\0');
    const ::ssize_t got = ::pread(fd_, text.data(), text.size(), 0);
    detail::require<IoError>(got == static_cast<::ssize_t>(text.size()), "cannot read the first ",
                             size, " bytes of training log '", path_, "': ",
                             got < 0 ? detail::os_reason(errno) : std::string("it is shorter"));
    const std::size_t header_end = text.find('\n');
    detail::require<IoError>(header_end != std::string::npos, "training log '", path_,
                             "': the checkpoint records ", size, " bytes, less than its header");
    std::size_t line_start = header_end + 1;
    for (long epoch = 1; epoch <= rows; ++epoch) {
      const std::string number = std::to_string(epoch) + ",";
      const std::size_t end = text.find('\n', line_start);
      detail::require<IoError>(end != std::string::npos && text.compare(line_start, number.size(),
                                                                        number) == 0,
                               "training log '", path_, "': its first ", size,
                               " bytes, as the checkpoint records, do not hold the rows of "
                               "epochs 1 to ", rows, " (row ", epoch, " is missing or does not "
                               "start with '", number, "'); the log or the checkpoint was "
                               "changed");
      line_start = end + 1;
    }
    detail::require<IoError>(line_start == text.size(), "training log '", path_, "': its first ",
                             size, " bytes, as the checkpoint records, hold more than the rows "
                             "of epochs 1 to ", rows, "; the log or the checkpoint was changed");
  }

  explicit TrainingLogFile(const std::string& path) : path_(path) {
    fd_ = detail::open_above_standard_streams(path.c_str(), O_RDWR | O_APPEND | O_CLOEXEC);
    detail::require<IoError>(fd_ >= 0, "cannot open training log '", path, "': ",
                             detail::os_reason(errno));
  }

  std::string path_;
  int fd_ = -1;
  long long size_ = 0, bytes_written_ = 0, writes_ = 0;
};

}  // namespace sbptt
