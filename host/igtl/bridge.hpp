#pragma once
// LCM -> OpenIGTLink (docs/igtl.md): each valid tool_pose_t becomes a TRANSFORM named the
// PLUS way ("PointerToReference"; a tip transform "PointerTipToReference" where a tip
// offset is configured), a tool that is not seen (any status but VALID) sends nothing;
// the valid tools of one tracker frame become one TDATA for the clients that asked;
// camera frames (image_frame_t, JPEG/PNG) become RGB IMAGE messages, optionally
// downscaled and rate limited, on the bridge's own image thread (decoding a 720p JPEG takes
// milliseconds: the LCM thread only hands the latest frame over, so poses never wait for
// an image). The host's surfaces (surface_mesh_t, ARNAV_SURFACE_<name>) become POLYDATA
// named `Organ`, `Tumour`, `Cut`, ... packed on the same thread, the latest per name (a
// newer mesh replaces one still waiting), kept by the server for GET_POLYDATA.
// on_pose/on_frame/on_surface/flush are called from the LCM thread only.
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "arnav/image_frame_t.hpp"
#include "arnav/surface_mesh_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "host/igtl/server.hpp"

namespace arnav::igtl {

struct BridgeOptions {
  std::map<std::string, std::string> device_names;    // tool name -> its TRANSFORM device name (overrides PLUS naming)
  std::map<std::string, Eigen::Vector3d> tips_Tool_mm; // tool name -> pivot-calibrated tip in the tool frame
  std::string image_device_name = "Image_Reference";
  int image_downscale = 1;        // 1: full size, 2: half width and height, ...
  double image_rate_hz = 0.0;     // 0: every frame received
  std::string tdata_device_name = "ARNav";
};

struct BridgeStats {
  std::uint64_t poses = 0;
  std::uint64_t transforms = 0;       // TRANSFORM messages made (tips included)
  std::uint64_t not_seen = 0;         // poses with a status other than VALID: nothing sent
  std::uint64_t unnamed = 0;          // poses whose name does not fit OpenIGTLink (reported once per tool)
  std::uint64_t tdata = 0;
  std::uint64_t frames = 0;
  std::uint64_t images = 0;
  std::uint64_t frames_rate_limited = 0;
  std::uint64_t frames_replaced = 0;     // a newer frame arrived before the image thread took it
  std::uint64_t frames_undecodable = 0;
  std::uint64_t surfaces = 0;            // surface_mesh_t received
  std::uint64_t polydata = 0;            // POLYDATA messages made
  std::uint64_t surfaces_replaced = 0;   // a newer mesh of the same name arrived before the thread took it
  std::uint64_t surfaces_rejected = 0;   // not in Ref, a name OpenIGTLink cannot carry, inconsistent counts or indices
  double polydata_pack_ms_total = 0.0;   // checking and packing the meshes (libopenigtlink Pack + CRC), on the image thread
  double polydata_pack_ms_max = 0.0;
};

// The POLYDATA of a host surface: device name from the mesh's name the PLUS way ("organ" ->
// "Organ", "tumour2" -> "Tumour2"), points in Reference (mm), one polygon per triangle, time
// stamp the model step's UTC time. nullopt with `why` when the mesh is not in "Ref", its
// name does not fit, its counts disagree with its arrays, an index is out of range or a
// position is not finite.
std::optional<Packet> polydata_from_surface(const surface_mesh_t& mesh, std::string& device_name, std::string& why);

class Bridge {
 public:
  Bridge(BridgeOptions options, Server& server, Server::Log log);
  ~Bridge();
  Bridge(const Bridge&) = delete;
  Bridge& operator=(const Bridge&) = delete;
  void on_pose(const tool_pose_t& pose);
  void on_frame(const image_frame_t& frame);
  void on_surface(const surface_mesh_t& mesh);
  // Sends the TDATA of a tracker frame still being collected (end of a log).
  void flush();
  BridgeStats stats() const;

 private:
  struct FrameGroup {
    bool open = false;
    std::int64_t frame_number = 0;
    std::int64_t wall_us = 0;
    std::size_t poses_seen = 0;
    std::size_t poses_expected = 0;   // poses of the previous frame of this source
    std::vector<TrackedElement> elements;
  };
  const std::string* device_name(const std::string& tool, const std::string& child, const std::string& parent);
  void add_to_frame(const tool_pose_t& pose, const std::vector<TrackedElement>& elements);
  void send_tdata(FrameGroup& group);
  void image_loop();
  void send_image(const image_frame_t& frame);
  void send_surface(const surface_mesh_t& mesh);

  BridgeOptions options_;
  Server& server_;
  Server::Log log_;
  std::map<std::string, std::string> names_;   // key tool|child|parent -> device name
  std::set<std::string> unnamed_;
  std::map<int, FrameGroup> frames_;           // per pose source (NDI, camera)
  std::int64_t last_image_capture_us_ = 0;
  mutable std::mutex mutex_;               // guards stats_, next_frame_, next_surfaces_, stopping_
  std::condition_variable image_wake_;
  std::optional<image_frame_t> next_frame_;
  std::map<std::string, surface_mesh_t> next_surfaces_;  // by name, the latest waiting for the image thread
  std::set<std::string> surface_reported_;   // names whose rejection was logged (image thread)
  bool stopping_ = false;
  BridgeStats stats_;
  std::thread image_thread_;
};

}  // namespace arnav::igtl
