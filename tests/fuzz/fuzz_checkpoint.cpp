// libFuzzer target: the checkpoint parser (sbptt/train/checkpoint.hpp).
//
// The input is the text of a checkpoint. It goes through `sbptt::parse_checkpoint` in double
// and in float, and through `load_checkpoint` from a file of those bytes. Expected outcomes are
// a checkpoint or a `sbptt::ParseError`; anything else (another exception, a sanitizer report,
// a broken invariant) is a finding.
//
// Invariants checked on success:
//   * the file loader agrees with the text parser (same outcome, same text written back);
//   * every number is finite, the counts agree (best parameters, Adam's moments: as many as the
//     parameters or none), Adam's second moments are ≥ 0, and the epochs are ordered
//     (since_best, best_epoch ≤ epoch);
//   * the shuffling state restores a generator;
//   * checkpoint_text of it parses back to a checkpoint whose text is the same bytes.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "fuzz_support.hpp"
#include "sbptt/train/checkpoint.hpp"

namespace {

using sbptt_fuzz::expect;

template <class Scalar>
std::optional<sbptt::Checkpoint<Scalar>> parsed(std::string_view text) {
  try {
    return sbptt::parse_checkpoint<Scalar>(text, "fuzz input");
  } catch (const sbptt::ParseError&) {
    return std::nullopt;
  }
}

template <class Scalar>
bool all_finite(const sbptt::Vector<Scalar>& v) {
  return v.allFinite();
}

template <class Scalar>
void check(std::string_view text, const sbptt_fuzz::ScratchDir& scratch) {
  const std::optional<sbptt::Checkpoint<Scalar>> c = parsed<Scalar>(text);

  const auto file = scratch.file("fuzz.checkpoint");
  sbptt_fuzz::write_bytes(file, text);
  std::optional<sbptt::Checkpoint<Scalar>> loaded;
  try {
    loaded = sbptt::load_checkpoint<Scalar>(file.string());
    expect(loaded.has_value(), "load_checkpoint found no file it was given");
  } catch (const sbptt::ParseError&) {
  }
  expect(c.has_value() == loaded.has_value(), "load_checkpoint and parse_checkpoint disagree");
  if (!c) return;
  const std::string written = sbptt::checkpoint_text(*c);
  expect(sbptt::checkpoint_text(*loaded) == written,
         "load_checkpoint and parse_checkpoint read different checkpoints");

  const auto n = c->params.size();
  expect(all_finite(c->params) && all_finite(c->best_params) && all_finite(c->adam_m) &&
             all_finite(c->adam_v),
         "parse_checkpoint accepted a non-finite number");
  expect(c->best_params.size() == 0 || c->best_params.size() == n,
         "parse_checkpoint accepted best parameters of another count");
  expect(c->adam_m.size() == c->adam_v.size(), "parse_checkpoint accepted moments of two sizes");
  expect((c->adam_v.array() >= Scalar(0)).all(), "parse_checkpoint accepted a negative adam_v");
  expect(std::isfinite(c->best_loss), "parse_checkpoint accepted a non-finite best loss");
  expect(c->since_best <= c->epoch && c->best_epoch <= c->epoch,
         "parse_checkpoint accepted a best epoch after the checkpoint's");
  expect(sbptt::Rng(0).restore(c->shuffle_state),
         "parse_checkpoint accepted a shuffling state the generator refuses");

  const std::optional<sbptt::Checkpoint<Scalar>> again = parsed<Scalar>(written);
  expect(again.has_value(), "checkpoint_text wrote a checkpoint its parser refuses");
  expect(sbptt::checkpoint_text(*again) == written,
         "checkpoint_text -> parse_checkpoint -> checkpoint_text changed the text");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const sbptt_fuzz::ScratchDir scratch;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  check<double>(text, scratch);
  check<float>(text, scratch);
  return 0;
}
