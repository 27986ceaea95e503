#pragma once
// A `can:` configuration shared by the decoder tests: a CANopen pedal with two switches
// and an analogue pedal, and an instrument whose button frame is its own liveness.
#include <string>

namespace arnav::can::test {

inline const std::string kPedalConfig = R"(can:
  interface: vcan0
  nodes:
    - name: pedal
      heartbeat: 0x10
      timeout_ms: 300
    - name: grasper
      periodic_id: 0x185
      timeout_ms: 100
  inputs:
    - name: pedal_cut
      node: pedal
      id: 0x190
      byte: 0
      bit: 0
      debounce_ms: 20
    - name: pedal_accept
      node: pedal
      id: 0x190
      byte: 0
      bit: 1
      active: low
      debounce_ms: 0
    - name: pedal_analog
      node: pedal
      id: 0x191
      byte: 1
      size: 2
      range: [200, 800]
      debounce_ms: 0
    - name: grasper_close
      node: grasper
      id: 0x185
      byte: 0
      bit: 7
      debounce_ms: 10
)";

}  // namespace arnav::can::test
