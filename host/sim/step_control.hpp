#pragma once
// Step control shared by the tissue models (docs/sim.md, "Step control"): a step that ends
// unhealthy (energy created, non-finite state, collapse) is undone and redone from the state
// it started from with 2, 4, ... times the configured substeps, up to the frame's budget:
// kMaxFactor (8) for a step of up to 1/60 s; a longer step has more wall time before the next
// one is due, so its budget is the same substep rate, 8x per 1/60 s of the step (1/30 s: 16x,
// 1/20 s: 24x, the last redo's factor being the budget itself), at most kMaxBudgetFactor
// (budget_factor(dt)).
// The factor that held is kept for the following steps while they need it and halved after
// kCalmSteps healthy steps at it (the tissue has calmed): a relaxed step that fails is redone
// at the finer factor again. A healthy step that spends most of the energy ledger's margin is
// redone finer too (kStrainedMarginShare). Only a step no factor within the budget holds
// stays unhealthy.
// Counted (redone steps, steps that no factor held, steps that ended at each factor) and
// named in the step's warning.
#include <algorithm>
#include <array>
#include <string>

#include "host/sim/step_health.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

class SubstepControl {
 public:
  static constexpr int kMaxFactor = 8;         // the budget of a step of up to 1/60 s
  static constexpr int kMaxBudgetFactor = 32;  // the budget of any step
  static constexpr int kLevels = 6;            // factors 1, 2, 4, 8, 16, 32 (a factor between two counts at the higher)
  static constexpr int kCalmSteps = 30;        // healthy steps at a factor before it is halved (0.5 s at 60 Hz)
  // A healthy step that creates more than this share of the energy ledger's margin left at
  // its start (StepSummary::energy_allowance_mN_mm at its end less the energy created before
  // it) is strained: redone finer while the budget allows, and not calm. The ledger is
  // cumulative, so a step control that waited for the stop would meet a margin spent by
  // earlier steps that no redo of the current one recovers; a steady state whose unconverged
  // energy stays put (XPBD at few iterations) spends nothing and is left alone (docs/sim.md
  // "Step control").
  static constexpr double kStrainedMarginShare = 0.5;
  bool strained(const StepSummary& s) const;

  // The largest factor a step of dt_s may use: kMaxFactor per 1/60 s of it, rounded down to
  // an integer, between kMaxFactor and kMaxBudgetFactor. (Before 2026-12-04 it was rounded
  // down to a power of two: a 1/20 s step got 16x, two thirds of the rate, and XPBD stopped
  // on a small liver that 24x holds; docs/benchmarks.md "Stress matrix on livers we did not
  // develop on".)
  static int budget_factor(double dt_s);
  // The same budget as a substep count for a model that knows the count it needs before the
  // step (the explicit mass-spring integrator's stability bound): kMaxFactor times the
  // configured substeps per 1/60 s of the step, not rounded, between kMaxFactor and
  // kMaxBudgetFactor times them.
  static int budget_substeps(int configured, double dt_s);
  // The budget's substep rate as a factor of the configured substeps (not rounded).
  static double budget_rate(double dt_s);

  // One step: save() keeps the state it starts from, step(factor) runs it with factor times
  // the configured substeps from the current state, restore() brings the saved state back
  // before a redo. max_factor: the budget (budget_factor of the step's dt). The returned
  // summary is the last attempt's; its wall time is the caller's.
  template <typename Save, typename Restore, typename Step>
  StepSummary run(Save&& save, Restore&& restore, Step&& step, int max_factor = kMaxFactor) {
    save();
    int factor = start_factor();
    StepSummary s = step(factor);
    std::string first;
    while ((!s.healthy || strained(s)) && retry_allowed(s) && factor < max_factor) {
      if (first.empty()) first = s.healthy ? strain_note(s) : s.warning.substr(0, 160);
      factor = std::min(2 * factor, max_factor);
      restore();
      ++redone_;
      s = step(factor);
    }
    finish(s, factor, first);
    return s;
  }

  // The model reset its energy ledger (nothing created from here on).
  void ledger_reset() { created_before_mN_mm_ = 0.0; }

  // Counts a step that a model ran at `factor` times its configured substeps by its own
  // choice, with no redo (the explicit mass-spring integrator within its stability bound).
  void count_step_at(int factor);

  int factor() const { return factor_; }  // the factor the next step starts from
  int redone_steps() const { return redone_; }
  int failed_steps() const { return failed_; }
  // Steps that ended at factor 1, 2, 4, 8, 16, 32 (healthy or not).
  const std::array<long long, kLevels>& steps_at_factor() const { return steps_at_; }
  // "steps at 1x/2x/4x/8x/16x/32x substeps: a/b/c/d/e/f, redone r, not held n".
  std::string counts() const;

 private:
  int start_factor();
  static bool retry_allowed(const StepSummary& s);
  std::string strain_note(const StepSummary& s) const;
  // The ledger's margin left at the step's start (allowance minus energy created before it,
  // at least 0) and the energy the step created.
  struct LedgerStep {
    double margin_mN_mm, spent_mN_mm;
  };
  LedgerStep ledger_step(const StepSummary& s) const;
  void finish(StepSummary& s, int factor, const std::string& first_warning);

  int factor_ = 1;
  int calm_ = 0;  // healthy steps at factor_ in a row
  bool relaxing_ = false;
  int redone_ = 0, failed_ = 0;
  double created_before_mN_mm_ = 0.0;  // the ledger's created energy at the end of the last held step
  std::array<long long, kLevels> steps_at_{};
};

}  // namespace arnav::host
