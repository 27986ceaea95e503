#include "host/sim/step_control.hpp"

#include <algorithm>
#include <cmath>

namespace arnav::host {
namespace {

int level_of(int factor) {
  int level = 0;
  while ((1 << level) < factor && level + 1 < SubstepControl::kLevels) ++level;
  return level;
}

}  // namespace

double SubstepControl::budget_rate(double dt_s) {
  return std::clamp(kMaxFactor * dt_s * 60.0 * (1.0 + 1e-6), double{kMaxFactor}, double{kMaxBudgetFactor});
}

int SubstepControl::budget_factor(double dt_s) { return static_cast<int>(std::floor(budget_rate(dt_s))); }

int SubstepControl::budget_substeps(int configured, double dt_s) {
  return static_cast<int>(std::floor(configured * budget_rate(dt_s)));
}

int SubstepControl::start_factor() {
  relaxing_ = factor_ > 1 && calm_ >= kCalmSteps;
  return relaxing_ ? factor_ / 2 : factor_;
}

bool SubstepControl::retry_allowed(const StepSummary& s) {
  // A configuration the model refuses outright, or a factorisation that failed, does not
  // change with more substeps.
  return s.termination != "refused_unstable_dt" && s.termination != "factorization_failed";
}

SubstepControl::LedgerStep SubstepControl::ledger_step(const StepSummary& s) const {
  return {std::max(s.energy_allowance_mN_mm - created_before_mN_mm_, 0.0), s.energy_created_mN_mm - created_before_mN_mm_};
}

bool SubstepControl::strained(const StepSummary& s) const {
  if (!(s.energy_allowance_mN_mm > 0.0)) return false;  // no ledger (the implicit FEMs)
  const LedgerStep l = ledger_step(s);
  return l.spent_mN_mm > kStrainedMarginShare * l.margin_mN_mm;
}

std::string SubstepControl::strain_note(const StepSummary& s) const {
  const LedgerStep l = ledger_step(s);
  const std::string share =
      l.margin_mN_mm > 0.0 ? std::to_string(std::lround(100.0 * l.spent_mN_mm / l.margin_mN_mm)) + " %" : "more than all";
  return "energy ledger: the step created " + share + " of the margin left";
}

void SubstepControl::finish(StepSummary& s, int factor, const std::string& first_warning) {
  ++steps_at_[static_cast<std::size_t>(level_of(factor))];
  if (!s.healthy) {
    ++failed_;
    return;  // the caller's run stops here; the factor stays where it was
  }
  if (factor != factor_ || relaxing_) calm_ = 0;  // a new level, or a relaxed step that needed the finer one again
  factor_ = factor;
  calm_ = strained(s) ? 0 : calm_ + 1;
  if (s.energy_allowance_mN_mm > 0.0) created_before_mN_mm_ = s.energy_created_mN_mm;
  if (!first_warning.empty()) {
    report(s, "step control: step redone with " + std::to_string(factor) + "x the substeps (" + first_warning +
                  "); kept until " + std::to_string(kCalmSteps) + " calm steps",
           false);
  } else if (factor > 1) {
    report(s, "step control: " + std::to_string(factor) + "x the substeps (" + counts() + ")", false);
  }
}

void SubstepControl::count_step_at(int factor) { ++steps_at_[static_cast<std::size_t>(level_of(factor))]; }

std::string SubstepControl::counts() const {
  std::string out = "steps at 1x/2x/4x/8x/16x/32x substeps: ";
  for (int l = 0; l < kLevels; ++l) {
    if (l > 0) out += '/';
    out += std::to_string(steps_at_[static_cast<std::size_t>(l)]);
  }
  return out + ", redone " + std::to_string(redone_) + ", not held " + std::to_string(failed_);
}

}  // namespace arnav::host
