#pragma once
// What the Simulator drives: the modelled Polaris (PolarisModel) or a recorded session
// acted out (ReplayDevice). Both turn host bytes into replies and can be reset.
#include <span>
#include <string>
#include <vector>

#include "hil_tests/polaris_sim/device_model.hpp"

namespace arnav::hil {

class SimDevice {
 public:
  virtual ~SimDevice() = default;
  virtual std::vector<PolarisModel::Reply> receive(std::span<const std::uint8_t> bytes, double now_s) = 0;
  virtual Bytes reset(double now_s) = 0;
  virtual int baud() const = 0;
  virtual void set_baud(int baud) = 0;
  virtual std::optional<double> first_tstart_s() const = 0;
  // The CLOCK_MONOTONIC time (s) of the simulator's time 0 (for a scenario's epoch_mono_us).
  virtual void set_clock_origin_mono_s(double /*t0_mono_s*/) {}
  // Faults that need the device's cooperation; a device that cannot model one returns
  // false (the Simulator reports it) rather than pretending.
  virtual bool force_errors(std::uint8_t /*code*/, int /*count*/) { return false; }
  virtual bool swallow_commands(int /*count*/) { return false; }
  virtual bool hide_tool(const std::string& /*tool*/, double /*until_s*/, bool /*out_of_volume*/) { return false; }
};

// The modelled device plus the command-level faults (ERROR replies, lost commands).
class ModelDevice : public SimDevice {
 public:
  explicit ModelDevice(PolarisModel& model) : model_(model) {}
  std::vector<PolarisModel::Reply> receive(std::span<const std::uint8_t> bytes, double now_s) override;
  Bytes reset(double now_s) override { return model_.reset(now_s); }
  int baud() const override { return model_.baud(); }
  void set_baud(int baud) override { model_.set_baud(baud); }
  std::optional<double> first_tstart_s() const override { return model_.first_tstart_s(); }
  void set_clock_origin_mono_s(double t0_mono_s) override { model_.set_clock_origin_mono_s(t0_mono_s); }
  bool force_errors(std::uint8_t code, int count) override;
  bool swallow_commands(int count) override;
  bool hide_tool(const std::string& tool, double until_s, bool out_of_volume) override;

 private:
  PolarisModel& model_;
  std::vector<std::uint8_t> line_;
  std::uint8_t error_code_ = 0;
  int errors_left_ = 0;
  int swallow_left_ = 0;
};

}  // namespace arnav::hil
