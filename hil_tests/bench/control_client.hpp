#pragma once
// The bench simulators' `inject` subcommand: one command to a running simulator's control
// socket (unix datagram), its answer printed on stdout.
#include <string>

namespace arnav::hil {

// Returns the exit code: 0 when the simulator answered "OK", 1 when there is no simulator at
// socket_path, no answer within 3 s or another answer, 2 when the path is too long. Messages
// start with "<program> inject: "; `no_simulator_hint` is appended to the no-simulator one.
int send_control_command(const std::string& program, const std::string& socket_path, const std::string& command,
                         const std::string& no_simulator_hint = "");

}  // namespace arnav::hil
