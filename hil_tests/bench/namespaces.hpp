#pragma once
// Private namespaces for the HIL bench: a mount namespace (so the simulator may
// bind-mount its pty over /dev/ttyS0 without touching the machine) and a network
// namespace with only loopback, multicast routed to lo, so LCM udpm traffic never
// leaves through a real interface.
#include <string>

namespace arnav::hil {

// Moves the calling process (call before it starts threads) into new mount and network
// namespaces. Returns an empty string on success, else why it could not (the caller
// skips). Idempotent within a process.
std::string enter_bench_namespaces();

// A fresh temporary folder for one test (under /tmp), removed by the caller if wanted.
std::string make_temp_dir(const std::string& prefix);

}  // namespace arnav::hil
