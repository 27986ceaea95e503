#include "appliance/serial/serial_transport.hpp"

#include <libserialport.h>

#include <cstdio>
#include <thread>

namespace arnav::ndi {
namespace {

std::string last_error() {
  char* msg = sp_last_error_message();
  std::string s = msg ? msg : "unknown error";
  sp_free_error_message(msg);
  return s;
}

std::string str(const char* s) { return s ? s : ""; }

}  // namespace

std::vector<PortInfo> list_ports() {
  sp_port** list = nullptr;
  if (sp_list_ports(&list) != SP_OK) throw PortError("cannot list serial ports: " + last_error());
  std::vector<PortInfo> out;
  for (sp_port** p = list; *p; ++p) {
    PortInfo info;
    info.name = str(sp_get_port_name(*p));
    info.description = str(sp_get_port_description(*p));
    switch (sp_get_port_transport(*p)) {
      case SP_TRANSPORT_USB: {
        info.transport = "usb";
        int vid = 0, pid = 0;
        if (sp_get_port_usb_vid_pid(*p, &vid, &pid) == SP_OK) {
          info.usb_vid = vid;
          info.usb_pid = pid;
        }
        info.usb_manufacturer = str(sp_get_port_usb_manufacturer(*p));
        info.usb_product = str(sp_get_port_usb_product(*p));
        info.usb_serial = str(sp_get_port_usb_serial(*p));
        break;
      }
      case SP_TRANSPORT_BLUETOOTH: info.transport = "bluetooth"; break;
      default: info.transport = "native"; break;
    }
    out.push_back(std::move(info));
  }
  sp_free_port_list(list);
  return out;
}

std::string describe_ports(const std::vector<PortInfo>& ports) {
  if (ports.empty()) return "  (no serial ports found)\n";
  std::string out;
  char ids[16];
  for (const auto& p : ports) {
    out += "  " + p.name + "  [" + p.transport + "] " + p.description;
    if (p.usb_vid && p.usb_pid) {
      std::snprintf(ids, sizeof ids, "%04X:%04X", *p.usb_vid, *p.usb_pid);
      out += std::string("  USB ") + ids;
      if (!p.usb_manufacturer.empty()) out += " " + p.usb_manufacturer;
      if (!p.usb_product.empty()) out += " " + p.usb_product;
      if (!p.usb_serial.empty()) out += " S/N " + p.usb_serial;
    }
    out += "\n";
  }
  return out;
}

bool port_exists(const std::string& name) {
  sp_port* port = nullptr;
  if (sp_get_port_by_name(name.c_str(), &port) != SP_OK) return false;
  sp_free_port(port);
  return true;
}

SerialTransport::SerialTransport(const std::string& name) : name_(name) {
  if (sp_get_port_by_name(name.c_str(), &port_) != SP_OK) {
    port_ = nullptr;
    throw PortError(name + ": no such serial port (" + last_error() + ")");
  }
  if (sp_open(port_, SP_MODE_READ_WRITE) != SP_OK) {
    const std::string err = last_error();
    sp_free_port(port_);
    port_ = nullptr;
    throw PortError(name + ": cannot open: " + err);
  }
  if (sp_set_baudrate(port_, 9600) != SP_OK || sp_set_bits(port_, 8) != SP_OK ||
      sp_set_parity(port_, SP_PARITY_NONE) != SP_OK || sp_set_stopbits(port_, 1) != SP_OK ||
      sp_set_flowcontrol(port_, SP_FLOWCONTROL_NONE) != SP_OK) {
    const std::string err = last_error();
    sp_close(port_);
    sp_free_port(port_);
    port_ = nullptr;
    throw PortError(name + ": cannot configure 9600 8N1: " + err);
  }
}

SerialTransport::~SerialTransport() {
  if (port_) {
    sp_close(port_);
    sp_free_port(port_);
  }
}

std::size_t SerialTransport::read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  // libserialport returns byte counts in its enum type: read them as int (an enum holding
  // a count is an invalid enum value; UBSan flags it).
  const int rc = sp_blocking_read_next(port_, buffer.data(), buffer.size(), static_cast<unsigned>(timeout.count()));
  if (rc < 0) throw PortLost(name_ + ": read failed: " + last_error());
  return static_cast<std::size_t>(rc);
}

void SerialTransport::write(std::span<const std::uint8_t> bytes) {
  const int rc = sp_blocking_write(port_, bytes.data(), bytes.size(), 1000);
  if (rc < 0) throw PortLost(name_ + ": write failed: " + last_error());
  if (static_cast<std::size_t>(rc) != bytes.size()) throw PortLost(name_ + ": write stalled");
}

void SerialTransport::set_baud(int baud) {
  if (sp_set_baudrate(port_, baud) != SP_OK)
    throw PortError(name_ + ": cannot set " + std::to_string(baud) + " baud: " + last_error());
}

void SerialTransport::send_break(std::chrono::milliseconds duration) {
  if (sp_start_break(port_) != SP_OK) throw PortLost(name_ + ": cannot start break: " + last_error());
  std::this_thread::sleep_for(duration);
  if (sp_end_break(port_) != SP_OK) throw PortLost(name_ + ": cannot end break: " + last_error());
}

void SerialTransport::drain_input() { sp_flush(port_, SP_BUF_INPUT); }

}  // namespace arnav::ndi
