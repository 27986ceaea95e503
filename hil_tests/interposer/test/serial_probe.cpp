// Test helper: talks to a (simulated) Polaris through unmodified libserialport, the way
// the appliance does: open, 9600 8N1, INIT, COMM to 115200, INIT, a break, RESET at 9600.
// Prints one line per step and exits 0 only if every step worked.
#include <libserialport.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

#include "appliance/ndi/crc16.hpp"

namespace {

std::string with_crc(const std::string& c) {
  char crc[8];
  std::snprintf(crc, sizeof crc, "%04X", arnav::ndi::crc16(c));
  return c + crc + "\r";
}

std::string read_reply(sp_port* port, unsigned timeout_ms) {
  std::string got;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline && (got.empty() || got.back() != '\r')) {
    char c;
    if (sp_blocking_read(port, &c, 1, 50) == 1) got.push_back(c);
  }
  return got;
}

bool step(const char* what, bool ok, const std::string& detail = "") {
  std::printf("%s: %s%s%s\n", what, ok ? "ok" : "FAILED", detail.empty() ? "" : " ", detail.c_str());
  std::fflush(stdout);
  return ok;
}

}  // namespace

// Frees the port on every exit path (the sanitizer build checks for leaks).
struct PortGuard {
  sp_port* port = nullptr;
  bool open = false;
  ~PortGuard() {
    if (open) sp_close(port);
    if (port) sp_free_port(port);
  }
};

int main(int argc, char** argv) {
  const char* path = argc > 1 ? argv[1] : "/dev/ttyS0";
  PortGuard guard;
  if (!step("get_port_by_name", sp_get_port_by_name(path, &guard.port) == SP_OK)) return 1;
  sp_port* port = guard.port;
  guard.open = sp_open(port, SP_MODE_READ_WRITE) == SP_OK;
  char* why = guard.open ? nullptr : sp_last_error_message();
  const bool opened = step("open", guard.open, why ? why : "");
  if (why) sp_free_error_message(why);
  if (!opened) return 1;
  sp_set_baudrate(port, 9600);
  sp_set_bits(port, 8);
  sp_set_parity(port, SP_PARITY_NONE);
  sp_set_stopbits(port, 1);
  sp_set_flowcontrol(port, SP_FLOWCONTROL_NONE);
  std::string c = with_crc("INIT:");
  sp_blocking_write(port, c.data(), c.size(), 1000);
  if (!step("INIT at 9600", read_reply(port, 3000) == "OKAYA896\r")) return 1;
  c = with_crc("COMM:50000");
  sp_blocking_write(port, c.data(), c.size(), 1000);
  if (!step("COMM 115200", read_reply(port, 3000) == "OKAYA896\r")) return 1;
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  sp_set_baudrate(port, 115200);
  c = with_crc("INIT:");
  sp_blocking_write(port, c.data(), c.size(), 1000);
  if (!step("INIT at 115200", read_reply(port, 3000) == "OKAYA896\r")) return 1;
  sp_set_baudrate(port, 9600);
  if (!step("start_break", sp_start_break(port) == SP_OK)) return 1;
  std::this_thread::sleep_for(std::chrono::milliseconds(250));
  if (!step("end_break", sp_end_break(port) == SP_OK)) return 1;
  const std::string reset = read_reply(port, 5000);
  if (!step("RESET after break", reset == "RESETBE6F\r", reset)) return 1;
  return 0;
}
