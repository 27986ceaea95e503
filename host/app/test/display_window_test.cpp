// display: {window: true}: the overlay shown in a GLFW window. Under a virtual X server
// (Xvfb, started by the test on a free display) the session opens the window, shows its
// frames, and the pixel the X server holds at the tumour's projected centroid is the
// overlay's tumour colour, equal to the frame the session produced. Without a display the
// session refuses with file:line, the key and what to do, and arnav-host exits 2. Skipped
// (with the reason) only where Xvfb is not installed.
#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <sstream>
#include <thread>


#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include "host/app/navigation_session.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/overlay/overlay_window.hpp"
#include "host/scene/scene.hpp"
#include "protocol/clock.hpp"

// X11 last: its macros (Success, None, ...) collide with Eigen's names.
#include <GLFW/glfw3.h>
#include <X11/Xlib.h>
#include <X11/Xutil.h>

// GLFW's X11 accessors (glfw3native.h would also want the Xrandr headers).
extern "C" {
Display* glfwGetX11Display(void);
Window glfwGetX11Window(GLFWwindow* window);
}

extern char** environ;

namespace arnav::host {
namespace {

using namespace arnav::host::test;

std::string find_xvfb() {
  const char* path = std::getenv("PATH");
  std::string p = path ? path : "/usr/bin:/bin";
  p += ":/usr/bin";
  std::size_t start = 0;
  while (start <= p.size()) {
    const std::size_t end = p.find(':', start);
    const std::string dir = p.substr(start, end == std::string::npos ? std::string::npos : end - start);
    const std::string exe = dir + "/Xvfb";
    if (!dir.empty() && ::access(exe.c_str(), X_OK) == 0) return exe;
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return {};
}

// A virtual X server on a display number it picks itself (-displayfd), for the test's life.
class Xvfb {
 public:
  Xvfb() {
    const std::string exe = find_xvfb();
    if (exe.empty()) return;
    int fds[2];
    if (::pipe(fds) != 0) return;
    const std::string fd = std::to_string(fds[1]);
    const char* argv[] = {exe.c_str(), "-displayfd", fd.c_str(), "-screen", "0", "1600x900x24", "-nolisten", "tcp", nullptr};
    if (posix_spawn(&pid_, exe.c_str(), nullptr, nullptr, const_cast<char* const*>(argv), environ) != 0) pid_ = -1;
    ::close(fds[1]);
    std::string number;
    char c;
    while (pid_ > 0 && ::read(fds[0], &c, 1) == 1 && c != '\n') number += c;
    ::close(fds[0]);
    if (!number.empty()) display_ = ":" + number;
  }
  ~Xvfb() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
  }
  const std::string& display() const { return display_; }

 private:
  pid_t pid_ = -1;
  std::string display_;
};

// The window's pixel as the X server holds it (what the screen shows), BGR.
cv::Vec3b x_server_pixel(GLFWwindow* w, int u, int v) {
  Display* d = glfwGetX11Display();
  const Window win = glfwGetX11Window(w);
  XSync(d, False);
  XImage* img = XGetImage(d, win, u, v, 1, 1, AllPlanes, ZPixmap);
  if (!img) return {0, 0, 0};
  const unsigned long p = XGetPixel(img, 0, 0);
  const cv::Vec3b bgr(static_cast<uchar>(p & img->blue_mask), static_cast<uchar>((p & img->green_mask) >> 8),
                      static_cast<uchar>((p & img->red_mask) >> 16));
  XDestroyImage(img);
  return bgr;
}

class DisplayWindow : public CoarseLiverSuite {};

TEST(DisplaySettings, ParsedAndChecked) {
  SessionFolder f("display_cfg");
  const SessionConfig c = load_session(f.session("display: {window: true, title: \"theatre 3\"}\n"));
  EXPECT_TRUE(c.display.window);
  EXPECT_EQ(c.display.title, "theatre 3");
  EXPECT_EQ(c.display.line, 14);
  EXPECT_FALSE(load_session(f.session()).display.window);  // headless is the default
  EXPECT_NE(session_error_of(f, "arnav_session_version: 1\ndisplay: {window: true}\n").find("bad.yaml:2: key 'display.window': a window shows the overlay: it needs a camera"),
            std::string::npos);
  EXPECT_NE(session_error_of(f, "arnav_session_version: 1\ndisplay: {fullscreen: true}\n").find("bad.yaml:2: key 'display.fullscreen': unknown key"),
            std::string::npos);
  EXPECT_NE(session_error_of(f, "arnav_session_version: 1\ndisplay: {window: maybe}\n").find("bad.yaml:2: key 'display.window'"),
            std::string::npos);
  EXPECT_NE(session_error_of(f, "arnav_session_version: 1\nmodel: {cpu_partition: half}\n").find("bad.yaml:2: key 'model.cpu_partition': must be 'auto'"),
            std::string::npos);
}

TEST_F(DisplayWindow, NoDisplayIsAClearErrorAndExit2) {
  SessionFolder f("display_none");
  const std::string path = f.session("display: {window: true}\n");
  const std::string saved_display = std::getenv("DISPLAY") ? std::getenv("DISPLAY") : "";
  const std::string saved_wayland = std::getenv("WAYLAND_DISPLAY") ? std::getenv("WAYLAND_DISPLAY") : "";
  ::unsetenv("DISPLAY");
  ::unsetenv("WAYLAND_DISPLAY");
  SessionOptions o;
  o.threaded = true;
  NavigationSession s(load_session(path), std::make_unique<Scene>(*scene_), o);
  try {
    s.start();
    ADD_FAILURE() << "start() opened a window without a display";
  } catch (const DisplayUnavailable& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("session.yaml:14: key 'display.window': no display"), std::string::npos) << what;
    EXPECT_NE(what.find("xvfb-run"), std::string::npos) << what;
    EXPECT_NE(what.find("remove 'display: {window: true}'"), std::string::npos) << what;
  }
  s.stop();
  // The executable: exit 2 and the same text.
  const char* bin = std::getenv("ARNAV_BINARY_DIR");
  ASSERT_NE(bin, nullptr);
  const std::string log = (f.dir / "host.log").string();
  const std::string cmd = std::string(bin) + "/host/app/arnav-host " + path + " --duration 5 --quiet > " + log + " 2>&1";
  const int rc = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(rc));
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  std::ifstream in(log);
  std::stringstream read;
  read << in.rdbuf();
  const std::string out = read.str();
  EXPECT_NE(out.find("key 'display.window': no display"), std::string::npos) << out;
  if (!saved_display.empty()) ::setenv("DISPLAY", saved_display.c_str(), 1);
  if (!saved_wayland.empty()) ::setenv("WAYLAND_DISPLAY", saved_wayland.c_str(), 1);
}

TEST_F(DisplayWindow, ShowsTheOverlayUnderXvfb) {
  Xvfb x;
  if (find_xvfb().empty()) GTEST_SKIP() << "Xvfb is not installed (Debian package xvfb, in scripts/deps): the window test needs a virtual X server";
  ASSERT_FALSE(x.display().empty()) << "Xvfb did not start (no display number on -displayfd)";
  ::setenv("DISPLAY", x.display().c_str(), 1);
  SessionFolder f("display_xvfb");
  // Unthreaded: the window lives on this thread, so the test can read the X server's pixels.
  SessionOptions o;
  o.threaded = false;
  o.keep_last_frame = true;
  NavigationSession s(load_session(f.session("display: {window: true}\n")), std::make_unique<Scene>(*scene_), o);
  s.open_window();
  FrameResult last;
  std::int64_t t = 1'000'000;
  for (int k = 0; k < 5; ++k, t += 16'667) {
    s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t);
    s.advance_model(t);
    last = s.render_frame(frame_msg(k, t), t + 2000);
  }
  EXPECT_EQ(s.window_frames(), 5);
  ASSERT_TRUE(last.row.tumour_px.has_value()) << "no tumour drawn: flags " << last.row.flags;
  const int u = static_cast<int>(std::lround(last.row.tumour_px->x)), v = static_cast<int>(std::lround(last.row.tumour_px->y));
  ASSERT_TRUE(u >= 0 && u < 1280 && v >= 0 && v < 720);
  const cv::Vec3b frame_px = last.image.at<cv::Vec3b>(v, u);
  // The tumour shows red through the veil on the session's frame ...
  EXPECT_GT(frame_px[2], frame_px[1] + 40) << frame_px;
  EXPECT_GT(frame_px[2], frame_px[0] + 40) << frame_px;
  // ... and the window on the X server shows that very frame (1:1, the window has the image's size).
  const nlohmann::json j = s.summary_json(1.0);
  ASSERT_TRUE(j.contains("display"));
  EXPECT_EQ(j["display"]["frames_shown"], 5);
  EXPECT_EQ(glfwGetCurrentContext(), nullptr);  // released after every frame: the renderer's EGL context comes next
  GLFWwindow* handle = s.window_handle();
  ASSERT_NE(handle, nullptr);
  int ww = 0, wh = 0;
  glfwGetWindowSize(handle, &ww, &wh);
  EXPECT_EQ(ww, 1280);
  EXPECT_EQ(wh, 720);
  for (const auto& [du, dv] : std::vector<std::pair<int, int>>{{0, 0}, {40, 0}, {0, 30}}) {
    const cv::Vec3b shown = x_server_pixel(handle, u + du, v + dv), drawn = last.image.at<cv::Vec3b>(v + dv, u + du);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(shown[c], drawn[c], 3) << "pixel (" << u + du << ", " << v + dv << ") channel " << c;
  }
  const cv::Vec3b shown = x_server_pixel(handle, u, v);
  EXPECT_GT(shown[2], shown[1] + 40) << shown;
  EXPECT_GT(shown[2], shown[0] + 40) << shown;
  // The banner row (top) differs from the tumour: the window is not one flat colour.
  EXPECT_NE(x_server_pixel(handle, 5, 700), shown);
}

TEST_F(DisplayWindow, LiveSessionShowsFramesFromItsRenderingThread) {
  Xvfb x;
  if (find_xvfb().empty()) GTEST_SKIP() << "Xvfb is not installed (Debian package xvfb, in scripts/deps): the window test needs a virtual X server";
  ASSERT_FALSE(x.display().empty());
  ::setenv("DISPLAY", x.display().c_str(), 1);
  SessionFolder f("display_live");
  SessionOptions o;
  o.threaded = true;
  NavigationSession s(load_session(f.session("display: {window: true, title: live}\n")), std::make_unique<Scene>(*scene_), o);
  s.start();
  for (int k = 0; k < 20; ++k) {
    const std::int64_t t = monotonic_us();
    s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t);
    s.submit_frame(frame_msg(k, t), t);
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (s.window_frames() + s.summary_json(1.0)["frames_dropped"].get<std::int64_t>() < 20 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  s.stop();
  EXPECT_EQ(s.failure(), "");
  const nlohmann::json j = s.summary_json(1.0);
  EXPECT_EQ(j["frames_displayed"].get<std::int64_t>() + j["frames_dropped"].get<std::int64_t>(), 20);
  EXPECT_EQ(j["display"]["frames_shown"], j["frames_displayed"]);
  EXPECT_GE(j["display"]["frames_shown"].get<std::int64_t>(), 3);  // how many of 20: the machine's load (frames dropped are counted)
  EXPECT_FALSE(j["display"]["closed_by_user"].get<bool>());
}

}  // namespace
}  // namespace arnav::host
