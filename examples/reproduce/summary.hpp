// reproduce: summary.csv and the results table, from the training logs of finished runs.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <sbptt/core/number_text.hpp>
#include <sbptt/train/training_log.hpp>

#include "grid.hpp"

namespace reproduce {

struct Summary {
  Run run;
  long epochs_done = 0;
  double final_test = NAN, min_test = NAN, final_train = NAN;
  double mean_seconds = NAN, total_seconds = 0;
  [[nodiscard]] std::string status() const {
    return epochs_done == run.epochs ? "ok" : "stopped";
  }
};

inline constexpr const char* summary_header =
    "task,complexity,method,clip,seed,epochs,final_test_loss,min_test_loss,final_train_loss,"
    "mean_seconds_per_epoch,total_seconds,status,run";

/// The fields of one row of a training log, checked against what the programs write
/// (docs/formats.md). The programs never log a NaN (a non-finite epoch has no row), so one
/// here, or a value no run can produce, is damage, not a result.
struct RowFields {
  const std::vector<std::string>& fields;
  const fs::path& csv;
  std::size_t line;      ///< 1 for the header
  sbptt::Method method;  ///< only the combined one logs cos_m_r and agree_fraction

  // The location is built only for a message: scan_finished reads every row of every run.
  [[nodiscard]] std::string where() const { return concat("'", csv.string(), "', line ", line); }
  [[nodiscard]] std::string field(std::size_t k) const {
    return concat(where(), ", field ", k + 1, " (", name(k), ")");
  }
  [[nodiscard]] static const std::string& name(std::size_t k) {
    static const std::vector<std::string> names = split(sbptt::TrainingLog::header, ',');
    return names[k];
  }
  double number(std::size_t k) const {
    try {
      return sbptt::detail::parse_finite<double>(fields[k], std::string());
    } catch (const sbptt::ParseError& e) {
      throw sbptt::ParseError(field(k) + e.what());
    }
  }
  double non_negative(std::size_t k) const {
    const double value = number(k);
    if (value < 0) throw sbptt::ParseError(concat(field(k), ": '", fields[k], "' is negative"));
    return value;
  }
  /// ‖v‖², which is `inf` where a finite norm squares past double's range.
  void norm2(std::size_t k) const {
    const std::string_view text = sbptt::detail::trim_blanks(fields[k]);
    if (text == "inf") return;
    try {
      non_negative(k);
    } catch (const sbptt::ParseError&) {
      throw sbptt::ParseError(concat(field(k), ": '", sbptt::detail::printable(text),
                                     "' is not a number >= 0 or 'inf'"));
    }
  }
  /// A mean of cosines or fractions: in [low, high] up to `slack`, and empty for every method
  /// but the combined one.
  void bounded(std::size_t k, double low, double high, double slack) const {
    if (method != sbptt::Method::Combined) {
      if (!fields[k].empty())
        throw sbptt::ParseError(concat(field(k), ": '", sbptt::detail::printable(fields[k]),
                                       "' where method ", sbptt::label(method), " logs nothing"));
      return;
    }
    const double value = number(k);
    if (value < low - slack || value > high + slack)
      throw sbptt::ParseError(concat(field(k), ": '", fields[k], "' is outside [",
                                     format_number(low), ", ", format_number(high), "]"));
  }
  /// The mean of the batches' cosines, `bounded` with a slack: builds before the cosine was
  /// clamped (test_core_sign.cpp) logged cosines past 1 by the rounding of float sums, where
  /// g_M and g_R nearly agree. Builds before 96694fb logged `nan` where float sums of squares
  /// overflowed: a diagnostic of a finished run whose losses stand, so such runs are kept.
  void cosine_mean(std::size_t k) const {
    if (method == sbptt::Method::Combined && fields[k] == "nan") return;
    bounded(k, -1, 1, 1e-3);
  }
};

/// Reads a finished training log (docs/programs.md): the header, then one row per epoch
/// numbered 1, 2, ..., every line ended by a newline. Throws ParseError naming the file, the
/// line and what is wrong (empty, cut off, a row that is not one).
inline Summary summarize(const Run& run, const fs::path& csv) {
  std::error_code error;
  if (fs::exists(csv, error) && !fs::is_regular_file(csv, error))
    throw sbptt::ParseError(concat("'", csv.string(), "' is not a regular file"));
  const std::string text = read_text(csv);
  if (text.empty()) throw sbptt::ParseError(concat("'", csv.string(), "' is empty"));
  if (text.back() != '\n')
    throw sbptt::ParseError(concat("'", csv.string(), "' is cut off (its last line has no end)"));
  const auto lines = split(text.substr(0, text.size() - 1), '\n');
  if (lines[0] != sbptt::TrainingLog::header)
    throw sbptt::ParseError(concat("'", csv.string(), "': the first line is not the training-log "
                                                      "header '",
                                   sbptt::TrainingLog::header, "'"));
  Summary s{run};
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto fields = split(lines[i], ',');
    const RowFields row{fields, csv, i + 1, run.method};
    if (fields.size() != 8)
      throw sbptt::ParseError(concat(row.where(), ": ", fields.size(), " fields, expected 8"));
    if (row.number(0) != static_cast<double>(i))
      throw sbptt::ParseError(concat(row.where(), ": epoch ", fields[0], ", expected ", i));
    row.number(1);
    const double train = row.number(2), test = row.number(3);
    row.norm2(4);
    row.cosine_mean(5);
    row.bounded(6, 0, 1, 1e-8);  // a mean of fractions: off only by its last digit
    const double seconds = row.non_negative(7);
    s.final_train = train;
    s.final_test = test;
    s.min_test = s.epochs_done == 0 ? test : std::min(s.min_test, test);
    s.total_seconds += seconds;
    ++s.epochs_done;
  }
  if (s.epochs_done > 0) s.mean_seconds = s.total_seconds / static_cast<double>(s.epochs_done);
  return s;
}

inline std::string summary_csv(const std::vector<Summary>& rows) {
  std::string text = std::string(summary_header) + "\n";
  auto value = [](double v) { return std::isnan(v) ? std::string() : format_exact(v); };
  for (const auto& s : rows) {
    char seconds[96];
    if (s.epochs_done > 0)
      std::snprintf(seconds, sizeof seconds, "%.6f,%.6f", s.mean_seconds, s.total_seconds);
    else
      std::snprintf(seconds, sizeof seconds, ",%.6f", s.total_seconds);
    text += concat(s.run.info().name, ",", format_number(s.run.complexity), ",",
                   sbptt::label(s.run.method), ",", sbptt::to_string(s.run.clip), ",", s.run.seed,
                   ",", s.epochs_done, ",", value(s.final_test), ",", value(s.min_test), ",",
                   value(s.final_train), ",", seconds, ",", s.status(), ",", s.run.name(), "\n");
  }
  return text;
}

inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// The results table: per task, complexity, method and clip mode, the final test loss over
/// seeds (median and min–max) and the mean training seconds per epoch.
inline void print_table(const std::vector<Summary>& rows) {
  std::printf("\n%-9s %-10s %-6s %-5s %5s  %-12s %-27s %9s  %s\n", "task", "complexity", "method",
              "clip", "seeds", "median test", "[min, max] over seeds", "s/epoch", "stopped");
  for (std::size_t i = 0; i < rows.size();) {
    std::size_t j = i;
    std::vector<double> finals;
    double seconds = 0;
    long seconds_count = 0, stopped = 0;
    const Run& r = rows[i].run;
    for (; j < rows.size() && rows[j].run.task == r.task &&
           same_number(rows[j].run.complexity, r.complexity) && rows[j].run.method == r.method &&
           rows[j].run.clip == r.clip;
         ++j) {
      if (!std::isnan(rows[j].final_test)) finals.push_back(rows[j].final_test);
      if (!std::isnan(rows[j].mean_seconds)) seconds += rows[j].mean_seconds, ++seconds_count;
      if (rows[j].status() != "ok") ++stopped;
    }
    char loss[32] = "-", spread[64] = "", time[32] = "-";
    if (!finals.empty()) {
      std::snprintf(loss, sizeof loss, "%.6g", median(finals));
      const auto [lo, hi] = std::minmax_element(finals.begin(), finals.end());
      if (finals.size() > 1) std::snprintf(spread, sizeof spread, "[%.6g, %.6g]", *lo, *hi);
    }
    if (seconds_count > 0)
      std::snprintf(time, sizeof time, "%.4f", seconds / static_cast<double>(seconds_count));
    std::printf("%-9s %-10s %-6s %-5s %5zu  %-12s %-27s %9s  %s\n", r.info().name,
                format_number(r.complexity).c_str(), std::string(sbptt::label(r.method)).c_str(),
                sbptt::to_string(r.clip).c_str(), j - i, loss, spread, time,
                stopped ? std::to_string(stopped).c_str() : "");
    i = j;
  }
}

}  // namespace reproduce
