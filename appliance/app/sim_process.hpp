#pragma once
// port: sim -> runs the bench simulator (arnav-polaris-sim) as a child process with
// --pty-link <tmpdir>/polaris plus the configured sim_args, and waits for the line
// "READY <pty path>" on its stdout. The child gets SIGTERM when this object goes away
// (and SIGKILL via PR_SET_PDEATHSIG if the appliance dies first).
#include <filesystem>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <sys/types.h>

namespace arnav::app {

class SimError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Finds the simulator: explicit command (config sim_command) if given, else
// arnav-polaris-sim next to self_exe, else on PATH. Throws SimError listing where it looked.
std::string find_simulator(const std::string& configured, const std::filesystem::path& self_exe);

class SimProcess {
 public:
  SimProcess(const std::string& program, const std::vector<std::string>& args, double ready_timeout_s = 20.0);
  ~SimProcess();
  SimProcess(const SimProcess&) = delete;
  SimProcess& operator=(const SimProcess&) = delete;

  const std::string& pty_path() const { return pty_path_; }
  // The symlink the simulator keeps pointing at its current pty (it makes a new pty
  // after a simulated cable pull): the name to (re)open.
  std::string link_path() const { return (dir_ / "polaris").string(); }
  pid_t pid() const { return pid_; }
  bool running();

 private:
  void cleanup();

  std::filesystem::path dir_;
  std::string pty_path_;
  pid_t pid_ = -1;
  int out_fd_ = -1;
  std::thread drain_;
};

}  // namespace arnav::app
