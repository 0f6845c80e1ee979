// The files a run writes do not depend on the host program's locale: a program that calls
// setlocale(LC_ALL, "") or std::locale::global (Qt applications do) still gets a training log
// and checkpoints that other tools and the next run can read. The truth is the same record
// written under the classic locale, and the parsers' own reading of the text.
#include <catch2/catch.hpp>

#include <clocale>
#include <cstdio>
#include <locale>
#include <sstream>
#include <string>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/train/checkpoint.hpp"
#include "sbptt/train/training_log.hpp"

using namespace sbptt;

namespace {

/// German number punctuation: a decimal comma and thousands grouped by points.
struct GermanPunctuation : std::numpunct<char> {
  char do_decimal_point() const override { return ','; }
  char do_thousands_sep() const override { return '.'; }
  std::string do_grouping() const override { return "\3"; }
};

/// Installs `locale` as the global C++ locale for the scope, and restores the old one.
class GlobalLocale {
public:
  explicit GlobalLocale(const std::locale& locale) : old_(std::locale::global(locale)) {}
  ~GlobalLocale() { std::locale::global(old_); }
  GlobalLocale(const GlobalLocale&) = delete;
  GlobalLocale& operator=(const GlobalLocale&) = delete;

private:
  std::locale old_;
};

/// Sets the C library's locale for the scope, and restores "C".
class CLocale {
public:
  explicit CLocale(const char* name) : set_(std::setlocale(LC_ALL, name) != nullptr) {}
  ~CLocale() { std::setlocale(LC_ALL, "C"); }
  CLocale(const CLocale&) = delete;
  CLocale& operator=(const CLocale&) = delete;
  [[nodiscard]] bool set() const { return set_; }

private:
  bool set_;
};

EpochRecord sample_record() {
  EpochRecord r;
  r.epoch = 1200;
  r.batch_loss = 0.5;
  r.train_loss = 0.25;
  r.test_loss = 0.125;
  r.update_norm2 = 1.5;
  r.cos_m_r = -0.75;
  r.agree_fraction = 0.625;
  r.seconds = 0.75;
  return r;
}

Checkpoint<double> sample_checkpoint() {
  Checkpoint<double> c;
  c.settings = {{"method", "C"}, {"batch", "8"}};
  c.epoch = 1200;
  Rng rng(7);
  c.shuffle_state = rng.state();
  c.log_bytes = 123456;
  c.skipped_batches = 1001;
  c.since_best = 100;
  c.best_epoch = 1100;
  c.best_loss = 0.5;
  c.last = sample_record();
  c.params = Vector<double>::LinSpaced(1001, -1.5, 1.5);
  c.best_params = c.params;
  c.adam_m = 0.5 * c.params;
  c.adam_v = c.params.cwiseAbs2();
  c.adam_t = 12345;
  return c;
}

}  // namespace

TEST_CASE("locale: a global C++ locale that groups thousands changes no file", "[train]") {
  const Checkpoint<double> c = sample_checkpoint();
  const std::string checkpoint_classic = checkpoint_text(c);
  const std::string row_classic = training_log_row(sample_record());
  const std::string state_classic = Rng(7).state();

  const GlobalLocale german(std::locale(std::locale::classic(), new GermanPunctuation));
  {
    std::ostringstream probe;  // the locale is in force: a plain stream groups
    probe << 1234567;
    REQUIRE(probe.str() == "1.234.567");
  }
  CHECK(detail::concat("epoch ", 1234567, ", x ", 0.5) == "epoch 1234567, x 0.5");
  CHECK(Rng(7).state() == state_classic);
  Rng restored(1);
  REQUIRE(restored.restore(state_classic));
  Rng original(7);
  CHECK(restored.bits() == original.bits());
  CHECK(training_log_row(sample_record()) == row_classic);

  const std::string text = checkpoint_text(c);
  CHECK(text == checkpoint_classic);
  const Checkpoint<double> back = parse_checkpoint<double>(text, "test.checkpoint");
  CHECK(back.epoch == 1200);
  CHECK(back.log_bytes == 123456);
  CHECK(back.skipped_batches == 1001);
  CHECK(back.adam_t == 12345);
  CHECK(back.params == c.params);
}

TEST_CASE("locale: a C locale with a decimal comma changes no file", "[train]") {
  // de_DE.UTF-8 is made for this test by localedef into the build tree (tests/CMakeLists.txt,
  // LOCPATH); its absence is a failure, not a skip.
  const Checkpoint<double> c = sample_checkpoint();
  const std::string checkpoint_classic = checkpoint_text(c);
  const std::string row_classic = training_log_row(sample_record());

  const CLocale german("de_DE.UTF-8");
  REQUIRE(german.set());
  char probe[16];
  std::snprintf(probe, sizeof probe, "%.1f", 0.5);  // the locale is in force: printf's comma
  REQUIRE(std::string(probe) == "0,5");
  CHECK(training_log_row(sample_record()) == row_classic);
  CHECK(checkpoint_text(c) == checkpoint_classic);
  CHECK(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint").params == c.params);
}
