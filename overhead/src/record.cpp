#include "record.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cinttypes>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>

#include "agv/recording/csv_stream.hpp"
#include "agv/recording/png_io.hpp"
#include "agv/recording/recording.hpp"
#include "inputs.hpp"
#include "live.hpp"

namespace agv::overhead_app {

namespace {

namespace fs = std::filesystem;

// Frames waiting per camera for its writer; a frame beyond them is dropped (counted).
constexpr std::size_t kWriterQueue = 4;
constexpr std::int64_t kSyncPeriodNs = 1'000'000'000;
// PNG compression: the fastest level, as the vehicle's recorder writes at 30 fps.
constexpr int kPngLevel = 1;

std::atomic<bool> g_record_stop{false};

extern "C" void on_record_signal(int) { g_record_stop.store(true); }

// Writes `text` under a temporary name, then renames it: a reader sees the whole file or none.
bool write_file_whole(const fs::path& path, const std::string& text, std::string* error) {
  const fs::path tmp = path.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  bool ok = fd >= 0;
  std::size_t done = 0;
  while (ok && done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    ok = n > 0;
    if (ok) done += static_cast<std::size_t>(n);
  }
  if (fd >= 0) ok = (::fsync(fd) == 0) && ok, ok = (::close(fd) == 0) && ok;
  std::error_code ec;
  if (ok) fs::rename(tmp, path, ec);
  if (!ok || ec) {
    fs::remove(tmp, ec);
    *error = path.string() + ": cannot write";
    return false;
  }
  return true;
}

std::string camera_yaml(const site::CeilingCamera& cam) {
  std::ostringstream f;
  f.precision(17);
  const CameraIntrinsics& k = cam.intrinsics;
  f << "# A camera fixed in the site: p_site = r_site_cam * p_cam + t_site_cam_mm\n"
    << "id: " << cam.id << "\nwidth_px: " << k.width_px << "\nheight_px: " << k.height_px
    << "\nfx: " << k.fx << "\nfy: " << k.fy << "\ncx: " << k.cx << "\ncy: " << k.cy
    << "\ndistortion: [" << k.k1 << ", " << k.k2 << ", " << k.p1 << ", " << k.p2 << ", " << k.k3
    << "]\nr_site_cam: [";
  for (std::size_t i = 0; i < 9; ++i) f << (i ? ", " : "") << cam.r_site_cam[i];
  f << "]\nt_site_cam_mm: [" << cam.t_site_cam_mm[0] << ", " << cam.t_site_cam_mm[1] << ", "
    << cam.t_site_cam_mm[2] << "]\n";
  return f.str();
}

// One camera's folder: a bounded queue of frames and the thread that writes them.
class FolderWriter {
 public:
  explicit FolderWriter(std::string dir) { c_.dir = std::move(dir); }
  ~FolderWriter() { close(); }

  bool open(std::string* error) {
    if (!csv_.open(c_.dir + "/frames.csv", recording::frames_csv_header(), error)) return false;
    synced_ns_ = monotonic_ns();
    thread_ = std::thread([this] { loop(); });
    return true;
  }
  void offer(LiveFrame&& f) {
    std::lock_guard<std::mutex> lock(m_);
    if (q_.size() >= kWriterQueue) {
      ++c_.frames_dropped;
      return;
    }
    q_.push_back(std::move(f));
    cv_.notify_one();
  }
  // Writes what is queued, then closes frames.csv.
  void close() {
    {
      std::lock_guard<std::mutex> lock(m_);
      closing_ = true;
      cv_.notify_one();
    }
    if (thread_.joinable()) thread_.join();
    std::string e;
    if (csv_.is_open() && !csv_.close(&e)) error(e);
  }
  const CameraRecordCounters& counters() const { return c_; }

 private:
  void loop() {
    for (;;) {
      LiveFrame f;
      {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait(lock, [this] { return !q_.empty() || closing_; });
        if (q_.empty()) return;
        f = std::move(q_.front());
        q_.pop_front();
      }
      write(f);
    }
  }
  void error(const std::string& e) {
    if (c_.write_errors++ == 0) std::fprintf(stderr, "agvloc-overhead record: %s\n", e.c_str());
  }
  void write(const LiveFrame& f) {
    if (f.t_ns <= last_t_ns_) {
      ++c_.frames_out_of_order;
      return;
    }
    char name[64];
    std::snprintf(name, sizeof name, "frames/%08" PRIu64 ".png", c_.frames_written);
    const fs::path final_path = fs::path(c_.dir) / name;
    const fs::path tmp = final_path.string() + ".tmp";
    std::string e;
    std::error_code ec;
    if (!png::write(tmp.string(), f.gray, &e, kPngLevel)) {
      fs::remove(tmp, ec);
      return error(e);
    }
    fs::rename(tmp, final_path, ec);
    if (ec) return error(final_path.string() + ": " + ec.message());
    std::string row;
    if (!recording::format_frame_row({f.t_ns, name}, &row, &e)) return error(e);
    last_t_ns_ = f.t_ns;
    ++c_.frames_written;
    csv_.add(row);
    if (!csv_.flush(&e)) error(e);
    const std::int64_t now = monotonic_ns();
    if (now - synced_ns_ >= kSyncPeriodNs) {
      synced_ns_ = now;
      if (!csv_.sync(&e)) error(e);
    }
  }

  CameraRecordCounters c_;
  recording::CsvStream csv_;
  std::int64_t last_t_ns_ = std::numeric_limits<std::int64_t>::min();
  std::int64_t synced_ns_ = 0;
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<LiveFrame> q_;
  bool closing_ = false;
  std::thread thread_;
};

}  // namespace

namespace {

// A folder a recording may be started in: absent or empty.
bool folder_free(const std::string& dir, std::string* error) {
  std::error_code ec;
  if (fs::exists(dir, ec) && !(fs::is_directory(dir, ec) && fs::is_empty(dir, ec))) {
    *error = dir + ": exists and is not an empty folder (a recording is never overwritten)";
    return false;
  }
  return true;
}

}  // namespace

bool start_recording_folder(const std::string& dir, const site::CeilingCamera& cam,
                            const site::Site& site, const std::string& source, std::string* error) {
  if (!folder_free(dir, error)) return false;
  std::error_code ec;
  fs::create_directories(fs::path(dir) / "frames", ec);
  if (ec) return (*error = dir + ": cannot create: " + ec.message(), false);
  recording::Meta meta;
  meta.camera.intrinsics = cam.intrinsics;  // the floor-camera mount does not apply: camera.yaml
  meta.landmark_size_mm = site.fleet.empty() ? 160.0 : site.fleet.front().tag_size_mm;
  meta.landmark_family = "tag36h11";
  meta.source = source;
  const std::string meta_text = recording::format_meta_yaml(meta);
  recording::Meta check;
  std::string e;
  if (!recording::parse_meta_yaml(meta_text, &check, &e))
    return (*error = dir + ": camera '" + cam.id + "' cannot be described: " + e, false);
  return write_file_whole(fs::path(dir) / "meta.yaml", meta_text, error) &&
         write_file_whole(fs::path(dir) / "camera.yaml", camera_yaml(cam), error) &&
         write_file_whole(fs::path(dir) / "odom.csv", recording::odom_csv_header(), error);
}

bool record_cameras(std::vector<LiveCamera>* cams, const site::Site& site,
                    const std::string& out_dir, const std::string& source,
                    const std::atomic<bool>& stop, std::int64_t duration_ns,
                    std::vector<CameraRecordCounters>* counters,
                    std::vector<CameraHealth>* cams_health, std::string* error) {
  std::vector<std::unique_ptr<FolderWriter>> writers;
  std::vector<FolderWriter*> by_site_camera(site.cameras.size(), nullptr);
  // Every folder checked before any is written: a refusal leaves nothing behind.
  for (const LiveCamera& c : *cams) {
    if (!folder_free((fs::path(out_dir) / c.id).string(), error)) return false;
  }
  for (const LiveCamera& c : *cams) {
    const std::string dir = (fs::path(out_dir) / c.id).string();
    if (!start_recording_folder(dir, site.cameras.at(c.site_camera), site, source, error))
      return false;
    writers.push_back(std::make_unique<FolderWriter>(dir));
    by_site_camera[c.site_camera] = writers.back().get();
  }
  for (auto& w : writers) {
    if (!w->open(error)) return false;
  }
  std::atomic<std::size_t> alive{cams->size()};
  CameraFeed feed(
      cams, "agvloc-overhead record",
      [&by_site_camera](LiveFrame&& f) { by_site_camera[f.camera]->offer(std::move(f)); },
      [&alive] { alive.fetch_sub(1); });
  const std::int64_t t_end =
      duration_ns > 0 ? monotonic_ns() + duration_ns : std::numeric_limits<std::int64_t>::max();
  feed.start();
  while (!stop.load() && alive.load() > 0 && monotonic_ns() < t_end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  feed.stop();
  counters->clear();
  for (auto& w : writers) {
    w->close();
    counters->push_back(w->counters());
  }
  *cams_health = feed.health();
  return true;
}

int run_record_command(const RecordArgs& args) {
  LiveInputs in;
  if (!start_live("record", args.config_path, args.site_path, on_record_signal, &in)) return 2;
  std::string err;
  std::fprintf(stderr, "agvloc-overhead record: %zu cameras into %s\n", in.cams.size(),
               args.out_dir.c_str());
  std::vector<CameraRecordCounters> counters;
  std::vector<CameraHealth> health;
  const std::string source = "agvloc-overhead record --site " + args.site_path;
  if (!record_cameras(&in.cams, in.site, args.out_dir, source, g_record_stop,
                      static_cast<std::int64_t>(std::llround(args.duration_s * 1e9)), &counters,
                      &health, &err))
    return command_fail("record", 2, err);
  std::uint64_t write_errors = 0;
  for (std::size_t i = 0; i < in.cams.size(); ++i) {
    const CameraRecordCounters& c = counters[i];
    write_errors += c.write_errors;
    std::printf(
        "agvloc-overhead record: %s: %llu frames written, %llu dropped (writer behind), %llu out "
        "of order, %llu write errors; camera %s\n",
        c.dir.c_str(), static_cast<unsigned long long>(c.frames_written),
        static_cast<unsigned long long>(c.frames_dropped),
        static_cast<unsigned long long>(c.frames_out_of_order),
        static_cast<unsigned long long>(c.write_errors),
        describe(in.cams[i].id, health[i]).c_str());
  }
  return write_errors == 0 ? 0 : 1;
}

}  // namespace agv::overhead_app
