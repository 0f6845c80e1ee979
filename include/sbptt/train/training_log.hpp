#pragma once
/// \file The per-epoch training log (DESIGN §4): CSV with header
/// `epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds`.
///
/// - batch_loss: mean over the epoch's mini-batches of the loss before each update;
/// - train_loss / test_loss: the whole train / test set evaluated after the epoch;
/// - update_norm2: mean over mini-batches of ‖vector fed to the optimizer‖² before clipping
///   (the reference's "update size");
/// - cos_m_r, agree_fraction: mean over mini-batches of cos(g_M, g_R) and of the share of
///   components whose signs agree; only the combined method computes both vectors, so the
///   fields are empty for the other methods;
/// - seconds: wall time of the epoch's updates (forward, sweeps, optimizer), without the
///   evaluation, as the reference logs it.
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "sbptt/core/atomic_file.hpp"

namespace sbptt {

/// One row of the training log.
struct EpochRecord {
  long epoch = 0;
  double batch_loss = 0;
  double train_loss = 0;
  double test_loss = 0;
  double update_norm2 = 0;
  std::optional<double> cos_m_r;
  std::optional<double> agree_fraction;
  double seconds = 0;
};

/// The rows of a run; `save` rewrites the whole file atomically, so a reader (or a crash)
/// never sees a truncated log.
class TrainingLog {
public:
  static constexpr const char* header =
      "epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds";

  void add(const EpochRecord& record) { rows_.push_back(record); }
  [[nodiscard]] const std::vector<EpochRecord>& rows() const { return rows_; }

  [[nodiscard]] std::string csv() const {
    std::string text = std::string(header) + "\n";
    char line[512];
    auto optional = [](const std::optional<double>& v) {
      char field[32] = "";
      if (v) std::snprintf(field, sizeof field, "%.9g", *v);
      return std::string(field);
    };
    for (const auto& r : rows_) {
      std::snprintf(line, sizeof line, "%ld,%.17g,%.17g,%.17g,%.9g,%s,%s,%.6f\n", r.epoch,
                    r.batch_loss, r.train_loss, r.test_loss, r.update_norm2,
                    optional(r.cos_m_r).c_str(), optional(r.agree_fraction).c_str(), r.seconds);
      text += line;
    }
    return text;
  }

  void save(const std::string& path) const { write_file_atomically(path, csv()); }

private:
  std::vector<EpochRecord> rows_;
};

}  // namespace sbptt
