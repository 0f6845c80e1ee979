#pragma once
/// \file The checkpoint of a training run (docs/training.md): everything needed to continue
/// bit for bit as if the run had not been interrupted.
///
/// Plain text, one `key value` per line, vectors as a count followed by one number per line:
///
///     sbptt-checkpoint 1
///     setting <name>=<value>        one line per run setting (method, batch, data fingerprints…)
///     epoch <e>                     epochs completed
///     shuffle <words>               the shuffling generator's state (mt19937-64, 313 words)
///     log_bytes <n>                 size of the training log after epoch e (-1: no log)
///     skipped_batches <n>           batches skipped so far (NonFinitePolicy::SkipBatch)
///     since_best <n>                evaluations since the best one (for the patience stop)
///     best_epoch <e>                0 when no evaluation yet
///     best_loss <x>
///     last <epoch> <batch> <train> <test> <norm2> <cos> <agree> <seconds>  ("-" = empty)
///     params <n>      θ, n lines
///     best_params <n> the best θ so far, n lines (0 before the first evaluation)
///     adam_t <t>      Adam's step count, then adam_m <n> and adam_v <n> with n lines each
///     end
///
/// Numbers use the round-trip precision of their type (%.17g double, %.9g float), so reading
/// them back restores every bit. The file is written with `write_file_atomically`: complete
/// and on disk, or not there.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <iterator>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/file_lock.hpp"
#include "sbptt/core/number_text.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/train/training_log.hpp"

namespace sbptt {

/// One setting a checkpoint must share with the run that resumes it ("method" = "C").
struct RunSetting {
  std::string name, value;
};

/// A run's state after a completed epoch; see the file comment for the format.
template <class Scalar>
struct Checkpoint {
  std::vector<RunSetting> settings;
  long epoch = 0;
  std::string shuffle_state;
  long long log_bytes = -1;
  long skipped_batches = 0;
  long since_best = 0;
  long best_epoch = 0;
  double best_loss = 0;
  std::optional<EpochRecord> last;
  Vector<Scalar> params, best_params, adam_m, adam_v;
  Index adam_t = 0;
};

namespace detail {

inline constexpr std::string_view checkpoint_magic = "sbptt-checkpoint 1";

/// How much of a setting's name or value a message shows, escaped: a damaged file must
/// neither drive the terminal nor cut the message at a NUL, nor flood it. Both sides of a
/// comparison get the same cap, and a run's settings (a MuJoCo target lists a number per
/// joint) stay far below it.
inline constexpr std::size_t setting_chars = 1000;

template <class Scalar>
void append_vector(std::string& text, const char* key, const Vector<Scalar>& values) {
  text += concat(key, " ", values.size(), "\n");
  for (Index i = 0; i < values.size(); ++i) {
    append_number(text, values(i));
    text += '\n';
  }
}

inline void append_optional(std::string& text, const std::optional<double>& value) {
  text += ' ';
  if (value) {
    append_number(text, *value);
  } else {
    text += '-';
  }
}

/// `text` as a whole number in [low, high] (`name` names it in errors): the range is checked
/// before the conversion, which is undefined for a double beyond a long's range.
inline long whole_number(std::string_view text, const std::string& where, std::string_view name,
                         double low, double high) {
  const double number = parse_finite<double>(text, where);
  require<ParseError>(number == std::floor(number), where, ": expected a whole number for '",
                      name, "'");
  require<ParseError>(number >= low && number <= high, where, ": ", name, " ", number,
                      "; expected ", low, " to ", high);
  return static_cast<long>(number);
}

/// Reads a checkpoint's lines in order, with errors naming the file and the line.
class CheckpointReader {
public:
  CheckpointReader(std::string_view text, std::string path) : text_(text), path_(std::move(path)) {}

  [[nodiscard]] bool at(std::string_view key) const {
    const std::string_view line = peek();
    return line.substr(0, line.find(' ')) == key;
  }

  /// The rest of the line after `key `.
  std::string_view value(std::string_view key) {
    const std::string_view line = next();
    require<ParseError>(line.substr(0, key.size()) == key &&
                            (line.size() == key.size() || line[key.size()] == ' '),
                        where(), ": '", printable(line, 60), "', expected '", key, " …'");
    return line.size() > key.size() ? line.substr(key.size() + 1) : std::string_view{};
  }

  // The line is read before `where()` names it: as two arguments of one call the two could be
  // evaluated in either order (GCC took `where()` first, one line early).
  template <class Number>
  Number number(std::string_view key) {
    const std::string_view text = value(key);
    return parse_finite<Number>(text, where());
  }

  /// A whole number in [low, high]: a value the run could not have written is damage.
  long integer(std::string_view key, double low = 0, double high = 1e15) {
    const std::string_view text = value(key);
    return whole_number(text, where(), key, low, high);
  }

  template <class Scalar>
  Vector<Scalar> vector(std::string_view key) {
    const long count = integer(key);
    require<ParseError>(count >= 0 && count <= 100'000'000, where(), ": ", count,
                        " numbers; expected 0 to 10^8");
    // A number a line: a count past the lines left is damage, found before its allocation.
    const auto lines_left = std::count(text_.begin() + static_cast<std::ptrdiff_t>(position_),
                                       text_.end(), '\n');
    require<ParseError>(count <= lines_left, where(), ": ", count, " numbers in ", key,
                        "; expected at most the ", lines_left, " lines left in the file");
    Vector<Scalar> values(count);
    for (long i = 0; i < count; ++i) {
      const std::string_view text = next();
      values(i) = parse_finite<Scalar>(text, where());
    }
    return values;
  }

  std::string_view next() {
    require<ParseError>(position_ < text_.size(), "checkpoint '", path_, "' ends after line ",
                        line_, "; expected more (the file is incomplete)");
    ++line_;  // the line being read, for where()
    const std::size_t end = text_.find('\n', position_);
    require<ParseError>(end != std::string_view::npos, where(), ": the line has no end");
    const std::string_view line = text_.substr(position_, end - position_);
    position_ = end + 1;
    return line;
  }

  [[nodiscard]] bool at_end() const { return position_ >= text_.size(); }

  [[nodiscard]] std::string where() const {
    return concat("checkpoint '", path_, "', line ", line_);
  }

private:
  [[nodiscard]] std::string_view peek() const {
    const std::size_t end = text_.find('\n', position_);
    return position_ < text_.size() ? text_.substr(position_, end - position_) : "";
  }

  std::string_view text_;
  std::string path_;
  std::size_t position_ = 0;
  long line_ = 0;
};

inline std::optional<double> optional_field(std::string_view field, const std::string& where) {
  if (field == "-") return std::nullopt;
  return parse_finite<double>(field, where);
}

/// A squared update norm: finite, or "inf" where a finite norm (up to 1.8e308) squared
/// overflows; the log writes it so, and the run goes on (clipping uses the norm itself).
inline double squared_norm_field(std::string_view field, const std::string& where) {
  if (field == "inf") return std::numeric_limits<double>::infinity();
  return parse_finite<double>(field, where);
}

}  // namespace detail

/// The checkpoint as text (see the file comment).
template <class Scalar>
[[nodiscard]] std::string checkpoint_text(const Checkpoint<Scalar>& c) {
  std::string text = std::string(detail::checkpoint_magic) + "\n";
  for (const RunSetting& s : c.settings) text += "setting " + s.name + "=" + s.value + "\n";
  text += detail::concat("epoch ", c.epoch, "\nshuffle ", c.shuffle_state, "\nlog_bytes ",
                         c.log_bytes, "\nskipped_batches ", c.skipped_batches, "\nsince_best ",
                         c.since_best, "\nbest_epoch ", c.best_epoch, "\nbest_loss ");
  detail::append_number(text, c.best_loss);
  text += "\nlast";
  if (c.last) {
    const EpochRecord& r = *c.last;
    text += detail::concat(' ', r.epoch);
    for (const std::optional<double> field :
         {std::optional(r.batch_loss), r.train_loss, r.test_loss, std::optional(r.update_norm2),
          r.cos_m_r, r.agree_fraction, std::optional(r.seconds)})
      detail::append_optional(text, field);
  }
  text += '\n';
  detail::append_vector(text, "params", c.params);
  detail::append_vector(text, "best_params", c.best_params);
  text += detail::concat("adam_t ", c.adam_t, "\n");
  detail::append_vector(text, "adam_m", c.adam_m);
  detail::append_vector(text, "adam_v", c.adam_v);
  return text + "end\n";
}

/// What a caller checks of a checkpoint's settings before its numbers are read: a checkpoint of
/// another run is refused for the setting that differs (the scalar type, say), not for a number
/// that the other run could write and this one cannot read.
using CheckpointSettingsCheck = std::function<void(const std::vector<RunSetting>&)>;

/// Parses `checkpoint_text`; `path` names the file in errors (`ParseError`). `check_settings`,
/// if set, sees the settings before any number is parsed.
template <class Scalar>
[[nodiscard]] Checkpoint<Scalar> parse_checkpoint(std::string_view text, const std::string& path,
                                                  const CheckpointSettingsCheck& check_settings =
                                                      {}) {
  detail::CheckpointReader in(text, path);
  detail::require<ParseError>(in.next() == detail::checkpoint_magic, "'", path,
                              "' is not an sbptt checkpoint (its first line is not '",
                              detail::checkpoint_magic, "')");
  Checkpoint<Scalar> c;
  while (in.at("setting")) {
    const std::string_view setting = in.value("setting");
    const std::size_t equals = setting.find('=');
    detail::require<ParseError>(equals != std::string_view::npos, in.where(),
                                ": expected 'setting name=value'");
    std::string name(setting.substr(0, equals));
    // A run writes each setting once; of two, either could be the one compared.
    for (std::size_t i = 0; i < c.settings.size(); ++i)
      detail::require<ParseError>(c.settings[i].name != name, in.where(), ": setting ",
                                  detail::printable(name, detail::setting_chars),
                                  " again (line ", i + 2,  // the settings follow line 1
                                  " gave it); expected each setting once");
    c.settings.push_back({std::move(name), std::string(setting.substr(equals + 1))});
  }
  // The settings are whole only where the epoch line follows them: a file cut among them is
  // incomplete (value throws), not a checkpoint of other settings.
  if (!in.at("epoch")) (void)in.value("epoch");
  if (check_settings) check_settings(c.settings);
  c.epoch = in.integer("epoch");
  c.shuffle_state = std::string(in.value("shuffle"));
  detail::require<ParseError>(Rng(0).restore(c.shuffle_state), in.where(),
                              ": not a state of the shuffling generator (mt19937-64's 313 "
                              "numbers)");
  c.log_bytes = in.integer("log_bytes", -1);  // −1: made without a log
  c.skipped_batches = in.integer("skipped_batches");
  c.since_best = in.integer("since_best", 0, static_cast<double>(c.epoch));
  c.best_epoch = in.integer("best_epoch", 0, static_cast<double>(c.epoch));
  const std::string best_epoch_line = in.where();
  c.best_loss = in.number<double>("best_loss");
  const std::string_view last = in.value("last");
  if (!last.empty()) {
    std::vector<std::string_view> fields;
    for (std::size_t start = 0; start <= last.size();) {
      const std::size_t end = std::min(last.find(' ', start), last.size());
      fields.push_back(last.substr(start, end - start));
      start = end + 1;
    }
    detail::require<ParseError>(fields.size() == 8, in.where(), ": 'last' has ", fields.size(),
                                " fields; expected 8");
    EpochRecord r;
    const std::string where = in.where();
    r.epoch = detail::whole_number(fields[0], where, "epoch of last", 0, 1e15);
    r.batch_loss = detail::parse_finite<double>(fields[1], where);
    r.train_loss = detail::optional_field(fields[2], where);
    r.test_loss = detail::optional_field(fields[3], where);
    r.update_norm2 = detail::squared_norm_field(fields[4], where);
    r.cos_m_r = detail::optional_field(fields[5], where);
    r.agree_fraction = detail::optional_field(fields[6], where);
    r.seconds = detail::parse_finite<double>(fields[7], where);
    detail::require<ParseError>(r.epoch == c.epoch, where, ": the last record is of epoch ",
                                r.epoch, "; expected the checkpoint's epoch ", c.epoch);
    c.last = r;
  }
  c.params = in.vector<Scalar>("params");
  // The other vectors are empty (no evaluation yet, an optimizer without moments) or as long.
  auto require_length = [&](const Vector<Scalar>& v, const char* key) {
    detail::require<ParseError>(v.size() == 0 || v.size() == c.params.size(), in.where(), ": ",
                                key, " has ", v.size(), " numbers; expected 0 or ",
                                c.params.size(), " (as params)");
  };
  c.best_params = in.vector<Scalar>("best_params");
  require_length(c.best_params, "best_params");
  detail::require<ParseError>((c.best_epoch > 0) == (c.best_params.size() > 0), best_epoch_line,
                              ": best_epoch ", c.best_epoch, " with ", c.best_params.size(),
                              " numbers in best_params; expected the best parameters exactly "
                              "when an epoch was best (best_epoch > 0)");
  c.adam_t = in.integer("adam_t");
  const std::string adam_t_line = in.where();
  c.adam_m = in.vector<Scalar>("adam_m");
  require_length(c.adam_m, "adam_m");
  detail::require<ParseError>((c.adam_t == 0) == (c.adam_m.size() == 0), adam_t_line,
                              ": adam_t ", c.adam_t, " with ", c.adam_m.size(),
                              " numbers in adam_m; expected moments exactly when Adam has taken "
                              "steps");
  c.adam_v = in.vector<Scalar>("adam_v");
  detail::require<ParseError>(c.adam_v.size() == c.adam_m.size(), in.where(), ": adam_v has ",
                              c.adam_v.size(), " numbers; expected ", c.adam_m.size(),
                              " (as adam_m)");
  detail::require<ParseError>((c.adam_v.array() >= Scalar(0)).all(), in.where(),
                              ": adam_v has a negative entry; expected squares' averages (>= 0)");
  const std::string_view end = in.next();
  detail::require<ParseError>(end == "end", in.where(), ": expected 'end'");
  if (!in.at_end()) {
    in.next();
    throw ParseError(detail::concat(in.where(), ": a line after 'end'; expected nothing"));
  }
  return c;
}

/// The caller's name for the setting `name` if `caller_names` (pairs {name, caller's name})
/// lists it, e.g. a program's flag; else `name`.
[[nodiscard]] inline std::string caller_name(const std::vector<RunSetting>& caller_names,
                                             const std::string& name) {
  for (const RunSetting& n : caller_names)
    if (n.name == name) return n.value;
  return name;
}

namespace detail {
/// Settings that `run_training` records since a later version: a checkpoint written before
/// lacks them, which says when it was written, not that it is another run's.
inline constexpr std::string_view settings_recorded_since_2026_12_07[] = {
    "steps", "loss_timing", "step_weight", "control_weight"};
}  // namespace detail

/// Throws `InvalidArgument` naming the first setting in which the checkpoint at `path`
/// differs from this run (`expected`), or one that only one of them has. A setting listed in
/// `caller_names` goes by the caller's name (`caller_name`).
inline void require_same_settings(const std::vector<RunSetting>& expected,
                                  const std::vector<RunSetting>& found, const std::string& path,
                                  const std::vector<RunSetting>& caller_names = {}) {
  auto named = [&](const std::string& name) { return caller_name(caller_names, name); };
  for (const RunSetting& want : expected) {
    const RunSetting* have = nullptr;
    for (const RunSetting& f : found)
      if (f.name == want.name) have = &f;
    const std::string name = named(want.name);
    if (have == nullptr) {
      const bool recorded_later =
          std::ranges::find(detail::settings_recorded_since_2026_12_07, want.name) !=
          std::end(detail::settings_recorded_since_2026_12_07);
      throw InvalidArgument(detail::concat(
          "checkpoint '", path, "' has no setting ", name, " (this run has ", name, " = ",
          want.value, recorded_later
                          ? "): it was written before 2026-12-07, when checkpoints began to "
                            "record the horizon and the objective; expected a checkpoint of "
                            "this version"
                          : "); expected a checkpoint of this run",
          " (remove it to start over)"));
    }
    if (have->value == want.value) continue;
    // The file's 17 digits of a number are noise to a reader; two numbers a run wrote differ
    // in their shortest forms too.
    std::string made = detail::shortest_if_round_trip(have->value);
    std::string now = detail::shortest_if_round_trip(want.value);
    if (made == now) {
      made = have->value;
      now = want.value;
    }
    throw InvalidArgument(detail::concat("checkpoint '", path, "' was made with ", name, " = ",
                                         detail::printable(made, detail::setting_chars),
                                         "; this run has ", name, " = ",
                                         detail::printable(now, detail::setting_chars),
                                         "; expected the same settings (remove it to start "
                                         "over)"));
  }
  for (const RunSetting& f : found) {
    bool known = false;
    for (const RunSetting& want : expected) known = known || want.name == f.name;
    detail::require(known, "checkpoint '", path, "' was made with setting ",
                    detail::printable(named(f.name), detail::setting_chars), " = ",
                    detail::printable(f.value, detail::setting_chars),
                    ", which this run does not have; expected a checkpoint of "
                    "this run (remove it to start over)");
  }
}

/// Saves `c` to `path` atomically and durably.
template <class Scalar>
void save_checkpoint(const std::string& path, const Checkpoint<Scalar>& c) {
  write_file_atomically(path, checkpoint_text(c));
}

/// Loads the checkpoint at `path`, or nothing when no file is there. Throws `IoError` when it
/// cannot be read and `ParseError` when it is not a complete checkpoint; `check_settings` as in
/// `parse_checkpoint`.
template <class Scalar>
[[nodiscard]] std::optional<Checkpoint<Scalar>> load_checkpoint(
    const std::string& path, const CheckpointSettingsCheck& check_settings = {}) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr && errno == ENOENT) return std::nullopt;
  detail::require<IoError>(file != nullptr, "cannot read checkpoint '", path, "': ",
                           detail::os_reason(errno));
  std::string text;
  char buffer[1 << 16];
  std::size_t got = 0;
  while ((got = std::fread(buffer, 1, sizeof buffer, file)) > 0) text.append(buffer, got);
  const bool failed = std::ferror(file) != 0;
  std::fclose(file);
  detail::require<IoError>(!failed, "reading checkpoint '", path, "' failed");
  return parse_checkpoint<Scalar>(text, path, check_settings);
}

/// `<checkpoint>.lock` beside the file `checkpoint` names (links followed); "" for an empty
/// path.
[[nodiscard]] inline std::string checkpoint_lock_path(const std::string& checkpoint) {
  return checkpoint.empty() ? std::string() : detail::final_target(checkpoint).string() + ".lock";
}

/// The lock of a run on its checkpoint, `checkpoint_lock_path(checkpoint)`, held until the
/// result is destroyed; none for an empty path. Two runs of one checkpoint would interleave
/// their rows in the log and leave it resumable by neither. Throws `IoError` when another run
/// holds it. A file system without locks runs unlocked.
[[nodiscard]] inline detail::FileLock lock_checkpoint(const std::string& checkpoint) {
  if (checkpoint.empty()) return {};
  const std::string lock_file = checkpoint_lock_path(checkpoint);
  detail::FileLock lock = detail::FileLock::take(lock_file, false);
  detail::require<IoError>(!lock.busy(), "checkpoint '", checkpoint, "' is in use: another run "
                           "holds '", lock_file, "' (the same command started twice?); "
                           "expected one run per checkpoint at a time");
  return lock;
}

}  // namespace sbptt
