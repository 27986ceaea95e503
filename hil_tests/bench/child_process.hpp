#pragma once
// A child process for multi-process HIL tests: started with posix_spawn (so it inherits
// the test's namespaces), stdout optionally captured line by line (for READY lines),
// stderr to a log file the test prints when something fails. Stopped with SIGTERM, then
// SIGKILL after a grace period.
#include <sys/types.h>

#include <optional>
#include <string>
#include <vector>

namespace arnav::hil {

class ChildProcess {
 public:
  // argv[0] is the executable path. extra_env entries "NAME=value" are added to (or
  // replace) the test's environment. stdout goes to a pipe if capture_stdout, else to the log.
  // fifo_priority > 0 starts the child under SCHED_FIFO at that priority (needs root).
  ChildProcess(std::vector<std::string> argv, std::vector<std::string> extra_env, std::string log_path,
               bool capture_stdout = false, int fifo_priority = 0);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  // Next stdout line (without newline), or nullopt after timeout_s or end of output.
  std::optional<std::string> read_line(double timeout_s);
  // True while the process has not exited.
  bool running();
  // Sends `signal`, waits up to timeout_s, then SIGKILL. Returns the exit code, or
  // 128+signal if killed by a signal; -1 if already reaped.
  int stop(int signal = 15, double timeout_s = 15.0);
  // Waits for exit without signalling; nullopt on timeout.
  std::optional<int> wait(double timeout_s);
  const std::string& log_path() const { return log_path_; }
  std::string log_tail(std::size_t max_bytes = 4000) const;

 private:
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  std::string buffer_;
  std::string log_path_;
  std::optional<int> exit_code_;
};

}  // namespace arnav::hil
