#pragma once
// One classic CAN 2.0 frame as the transports deliver it, independent of the kernel's
// struct can_frame (which only exists where linux/can.h is included: the SocketCAN
// transport and the bench shim). Error frames carry the SocketCAN error class in `id`
// (CAN_ERR_* bits) and its details in data[], as the kernel reports them.
#include <array>
#include <cstdint>
#include <string>

namespace arnav::can {

inline constexpr std::uint32_t kMaxStandardId = 0x7FF;
inline constexpr std::uint32_t kMaxExtendedId = 0x1FFFFFFF;

// SocketCAN error classes (linux/can/error.h values; kept here so the decoder and the
// candump reader do not depend on kernel headers).
namespace err {
inline constexpr std::uint32_t kTxTimeout = 0x001;
inline constexpr std::uint32_t kLostArb = 0x002;
inline constexpr std::uint32_t kCrtl = 0x004;       // controller problem, details in data[1]
inline constexpr std::uint32_t kProt = 0x008;
inline constexpr std::uint32_t kTrx = 0x010;
inline constexpr std::uint32_t kAck = 0x020;
inline constexpr std::uint32_t kBusOff = 0x040;
inline constexpr std::uint32_t kBusError = 0x080;
inline constexpr std::uint32_t kRestarted = 0x100;
// data[1] bits of kCrtl
inline constexpr std::uint8_t kCrtlRxOverflow = 0x01;
inline constexpr std::uint8_t kCrtlTxOverflow = 0x02;
inline constexpr std::uint8_t kCrtlRxWarning = 0x04;
inline constexpr std::uint8_t kCrtlTxWarning = 0x08;
inline constexpr std::uint8_t kCrtlRxPassive = 0x10;
inline constexpr std::uint8_t kCrtlTxPassive = 0x20;
inline constexpr std::uint8_t kCrtlActive = 0x40;
// Every class above: what the SocketCAN transport asks for with CAN_RAW_ERR_FILTER.
inline constexpr std::uint32_t kAllClasses = 0x1FF;
}  // namespace err

struct CanFrame {
  std::uint32_t id = 0;   // 11 or 29 bits; for error frames the error class bits
  bool extended = false;  // 29-bit identifier
  bool remote = false;    // RTR: no data, dlc is the requested length
  bool error = false;     // error frame (SocketCAN CAN_ERR_FLAG)
  std::uint8_t dlc = 0;   // 0-8
  std::array<std::uint8_t, 8> data{};

  friend bool operator==(const CanFrame& a, const CanFrame& b) {
    if (a.id != b.id || a.extended != b.extended || a.remote != b.remote || a.error != b.error || a.dlc != b.dlc) return false;
    if (a.remote) return true;
    for (int i = 0; i < a.dlc; ++i)
      if (a.data[static_cast<std::size_t>(i)] != b.data[static_cast<std::size_t>(i)]) return false;
    return true;
  }
};

// candump's compact notation: "123#DEADBEEF", "1ABCDEF0#00", "123#R", "123#R4",
// error frames "20000040#0000000000000000" (CAN_ERR_FLAG | class, 8 data bytes).
std::string to_candump(const CanFrame& f);

}  // namespace arnav::can
