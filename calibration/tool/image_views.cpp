#include "calibration/tool/image_views.hpp"

#include <algorithm>
#include <cctype>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib::tool {

std::vector<std::filesystem::path> list_images(const std::filesystem::path& folder) {
  std::error_code ec;
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(folder, ec)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".tif" || ext == ".tiff") {
      files.push_back(e.path());
    }
  }
  if (ec) throw CalibError(folder.string() + ": cannot read the image folder (" + ec.message() + ")");
  if (files.empty()) throw CalibError(folder.string() + ": no images (png, jpg, bmp, tif) in this folder");
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<ImageView> observe_images(const std::vector<std::filesystem::path>& images, const BoardLayout& layout,
                                      cv::Size& image_size) {
  std::vector<ImageView> views;
  for (const auto& path : images) {
    ImageView v;
    v.name = path.string();
    const cv::Mat gray = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (gray.empty()) {
      v.observation.reason = "unreadable image (not a valid image file)";
    } else if (!image_size.empty() && gray.size() != image_size) {
      v.observation.reason = "image is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) + ", the others " +
                             std::to_string(image_size.width) + "x" + std::to_string(image_size.height);
    } else {
      image_size = gray.size();
      v.observation = detect_board(gray, layout);
    }
    views.push_back(v);
  }
  return views;
}

std::vector<ImageView> observe_camera(int index, const BoardLayout& layout, int wanted, int max_frames, int every,
                                      cv::Size& image_size) {
  cv::VideoCapture cap(index);
  if (!cap.isOpened()) {
    throw CalibError("camera " + std::to_string(index) + ": cannot open (is it connected, /dev/video" +
                     std::to_string(index) + " readable?)");
  }
  std::vector<ImageView> views;
  int found = 0;
  cv::Mat frame, gray;
  for (int i = 0; i < max_frames && found < wanted; ++i) {
    if (!cap.read(frame) || frame.empty()) {
      throw CalibError("camera " + std::to_string(index) + ": frame " + std::to_string(i) + " could not be read");
    }
    if (i % std::max(every, 1) != 0) continue;
    if (frame.channels() == 1) {
      gray = frame;
    } else {
      cv::cvtColor(frame, gray, frame.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
    }
    image_size = gray.size();
    ImageView v;
    v.name = "camera frame " + std::to_string(i);
    v.observation = detect_board(gray, layout);
    if (v.observation.found) ++found;
    views.push_back(v);
  }
  return views;
}

}  // namespace arnav::calib::tool
