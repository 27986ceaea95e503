#include "appliance/ndi/error_codes.hpp"

namespace arnav::ndi {

ErrorCodeInfo error_code_info(std::uint8_t code) {
  switch (code) {
    case 0x01: return {"INVALID_COMMAND", "invalid command"};
    case 0x02: return {"COMMAND_TOO_LONG", "command too long"};
    case 0x03: return {"COMMAND_TOO_SHORT", "command too short"};
    case 0x04: return {"BAD_COMMAND_CRC", "invalid CRC calculated for command"};
    case 0x05: return {"COMMAND_TIMEOUT", "time-out on command execution"};
    case 0x06: return {"COMM_SETTINGS_FAILED", "unable to set up new communication parameters"};
    case 0x07: return {"WRONG_PARAMETER_COUNT", "incorrect number of parameters"};
    case 0x08: return {"INVALID_PORT_HANDLE", "invalid port handle selected"};
    case 0x09: return {"INVALID_PRIORITY", "invalid tracking priority selected"};
    case 0x0A: return {"INVALID_LED", "invalid LED selected"};
    case 0x0B: return {"INVALID_LED_STATE", "invalid LED state selected"};
    case 0x0C: return {"INVALID_IN_MODE", "command invalid in current operating mode"};
    case 0x0D: return {"NO_TOOL_ON_HANDLE", "no tool assigned to the port handle"};
    case 0x0E: return {"HANDLE_NOT_INITIALISED", "port handle not initialised"};
    case 0x0F: return {"HANDLE_NOT_ENABLED", "port handle not enabled"};
    case 0x10: return {"SYSTEM_NOT_INITIALISED", "system not initialised"};
    case 0x11: return {"CANNOT_STOP_TRACKING", "unable to stop tracking"};
    case 0x12: return {"CANNOT_START_TRACKING", "unable to start tracking"};
    case 0x13: return {"CANNOT_INITIALISE_PORT", "unable to initialise the port handle"};
    case 0x23: return {"PARAMETER_OUT_OF_RANGE", "parameter out of range"};
    case 0x28: return {"TOO_MANY_TOOLS", "too many tools of this type"};
    case 0x2B: return {"HANDLE_ALLOCATION_FAILED", "no port handle available"};
    case 0x2C: return {"HANDLE_NOT_ALLOCATED", "port handle not allocated"};
    case 0x2D: return {"HANDLE_ALREADY_ALLOCATED", "port handle already allocated"};
    case 0x30: return {"PORT_HAS_HANDLE", "port already has a handle"};
    case 0x33: return {"FEATURE_NOT_AVAILABLE", "feature not available"};
    case 0x41: return {"TOOL_DEFINITION_ERROR", "tool definition file error"};
    case 0xF1: return {"TOO_MUCH_INFRARED", "too much environmental infrared"};
    default: return {"UNKNOWN_ERROR", "unknown error code"};
  }
}

}  // namespace arnav::ndi
