#pragma once
// How arnav-host connects to the bus (docs/overlay.md, docs/protocol.md "Sealed bus"): the
// handlers that hand decoded messages to the status monitor's tracker or to the navigation
// session, and connect_session, which subscribes a session to every channel it reads and
// routes the sealed bus's drops to its security banner. Only messages the bus accepted reach
// a handler (seal::SealedLcm); a dropped one reaches the session as its verdict and channel.
#include <iostream>
#include <string>

#include <lcm/lcm-cpp.hpp>

#include "host/app/navigation_session.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace arnav::host {

// Poses, health and events to whatever tracks them (the status table's tracker or the session).
template <class Sink>
struct StatusHandler {
  Sink& sink;
  bool print_events;
  void pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* msg) { sink.on_pose(*msg, monotonic_us()); }
  void health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* msg) { sink.on_health(*msg, monotonic_us()); }
  void event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* msg) {
    sink.on_event(*msg);
    if (print_events) std::cout << "event " << msg->source << " " << msg->code << ": " << msg->text << std::endl;
  }
};

struct SessionHandler : StatusHandler<NavigationSession> {
  void frame(const lcm::ReceiveBuffer*, const std::string&, const image_frame_t* msg) { sink.submit_frame(*msg, monotonic_us()); }
  void input(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* msg) { sink.on_input(*msg, monotonic_us()); }
  void cloud(const lcm::ReceiveBuffer* rbuf, const std::string& channel) { sink.on_cloud(rbuf->data, rbuf->data_size, channel, monotonic_us()); }
};

// Subscribes handler.sink to poses, health, events, inputs, the swab's channel and (when
// frame_channel is not empty) the camera's frames; every message the bus drops goes to
// the session's banner (NavigationSession::on_bus_drop) at its receive time.
inline void connect_session(seal::SealedLcm& bus, SessionHandler& handler, const std::string& frame_channel) {
  StatusHandler<NavigationSession>* status = &handler;
  bus.subscribe(std::string(channels::kPoseRegex), &SessionHandler::pose, status);
  bus.subscribe(std::string(channels::kHealthRegex), &SessionHandler::health, status);
  bus.subscribe(std::string(channels::kEvents), &SessionHandler::event, status);
  if (!frame_channel.empty()) bus.subscribe(frame_channel, &SessionHandler::frame, &handler);
  bus.subscribe(std::string(channels::kInput), &SessionHandler::input, &handler);
  bus.subscribe(std::string(channels::kInputState), &SessionHandler::input, &handler);
  if (!handler.sink.swab_channel().empty()) bus.subscribe(handler.sink.swab_channel(), &SessionHandler::cloud, &handler);
  NavigationSession& session = handler.sink;
  bus.on_drop([&session](seal::Verdict v, const std::string& channel) { session.on_bus_drop(v, channel, monotonic_us()); });
}

}  // namespace arnav::host
