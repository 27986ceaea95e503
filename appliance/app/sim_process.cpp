#include "appliance/app/sim_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>

namespace arnav::app {
namespace {

bool executable(const std::filesystem::path& p) { return ::access(p.c_str(), X_OK) == 0 && std::filesystem::is_regular_file(p); }

}  // namespace

std::string find_simulator(const std::string& configured, const std::filesystem::path& self_exe) {
  if (!configured.empty()) {
    if (configured.find('/') != std::string::npos && !executable(configured))
      throw SimError("sim_command '" + configured + "' is not an executable file");
    return configured;
  }
  std::string looked;
  std::error_code ec;
  const auto self = std::filesystem::canonical(self_exe, ec);
  if (!ec) {
    const auto beside = self.parent_path() / "arnav-polaris-sim";
    if (executable(beside)) return beside.string();
    looked += beside.string() + ", ";
    // Build tree layout: build/<kind>/appliance/app/arnav-appliance and
    // build/<kind>/hil_tests/polaris_sim/arnav-polaris-sim.
    const auto in_tree = self.parent_path().parent_path().parent_path() / "hil_tests" / "polaris_sim" / "arnav-polaris-sim";
    if (executable(in_tree)) return in_tree.string();
    looked += in_tree.string() + ", ";
  }
  if (const char* path = std::getenv("PATH")) {
    std::string p(path);
    std::size_t start = 0;
    while (start <= p.size()) {
      std::size_t end = p.find(':', start);
      if (end == std::string::npos) end = p.size();
      const auto candidate = std::filesystem::path(p.substr(start, end - start)) / "arnav-polaris-sim";
      if (end > start && executable(candidate)) return candidate.string();
      start = end + 1;
    }
  }
  throw SimError("arnav-polaris-sim not found (looked at " + looked +
                 "and on PATH); build target arnav-polaris-sim or set sim_command in the configuration");
}

SimProcess::SimProcess(const std::string& program, const std::vector<std::string>& args, double ready_timeout_s) {
  char tmpl[] = "/tmp/arnav-sim-XXXXXX";
  if (!::mkdtemp(tmpl)) throw SimError(std::string("cannot create a temporary folder: ") + std::strerror(errno));
  dir_ = tmpl;
  const std::string link = (dir_ / "polaris").string();
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) throw SimError("pipe failed");
  std::vector<std::string> argv_s = {program, "--pty-link", link};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  pid_ = ::fork();
  if (pid_ < 0) throw SimError("fork failed");
  if (pid_ == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    // Own process group: a Ctrl-C meant for the appliance must not kill the device
    // before the appliance has stopped tracking; the appliance ends it afterwards.
    ::setpgid(0, 0);
    ::dup2(pipe_fds[1], STDOUT_FILENO);
    std::vector<char*> argv;
    for (auto& s : argv_s) argv.push_back(s.data());
    argv.push_back(nullptr);
    ::execvp(argv[0], argv.data());
    std::fprintf(stderr, "arnav-appliance: cannot run %s: %s\n", argv[0], std::strerror(errno));
    ::_exit(127);
  }
  ::close(pipe_fds[1]);
  out_fd_ = pipe_fds[0];

  std::string buffer;
  bool exited = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(ready_timeout_s);
  while (pty_path_.empty()) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{out_fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
    char chunk[512];
    const ssize_t n = ::read(out_fd_, chunk, sizeof chunk);
    if (n <= 0) {  // the simulator exited
      exited = true;
      break;
    }
    buffer.append(chunk, static_cast<std::size_t>(n));
    std::size_t nl;
    while ((nl = buffer.find('\n')) != std::string::npos) {
      const std::string line = buffer.substr(0, nl);
      buffer.erase(0, nl + 1);
      if (line.rfind("READY ", 0) == 0) {
        pty_path_ = line.substr(6);
        break;
      }
      std::cerr << "[sim] " << line << "\n";
    }
  }
  if (pty_path_.empty()) {
    cleanup();
    char secs[32];
    std::snprintf(secs, sizeof secs, "%.0f", ready_timeout_s);
    throw SimError("simulator '" + program + "' " + (exited ? "exited" : std::string("timed out after ") + secs + " s") +
                   " without printing 'READY <pty path>'");
  }
  // Keep reading its stdout so it never blocks on a full pipe.
  drain_ = std::thread([fd = out_fd_] {
    char chunk[512];
    while (::read(fd, chunk, sizeof chunk) > 0) {
    }
  });
}

bool SimProcess::running() {
  if (pid_ <= 0) return false;
  int status = 0;
  return ::waitpid(pid_, &status, WNOHANG) == 0;
}

SimProcess::~SimProcess() { cleanup(); }

void SimProcess::cleanup() {
  if (pid_ > 0) {
    ::kill(pid_, SIGTERM);
    int status = 0;
    bool gone = false;
    for (int i = 0; i < 200 && !gone; ++i) {  // up to 2 s
      gone = ::waitpid(pid_, &status, WNOHANG) != 0;
      if (!gone) ::usleep(10000);
    }
    if (!gone) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, &status, 0);
    }
    pid_ = -1;
  }
  if (drain_.joinable()) drain_.join();
  if (out_fd_ >= 0) {
    ::close(out_fd_);
    out_fd_ = -1;
  }
  std::error_code ec;
  if (!dir_.empty()) std::filesystem::remove_all(dir_, ec);
  dir_.clear();
}

}  // namespace arnav::app
