// fovea-map-link: the stream of the map's bricks over real sockets (issue 26,
// docs/map-delta.md), in one process so that both ends can be watched: the
// service (firmware::Service, `fovead serve`'s runtime) on the mock camera with
// foveation.source = map, and an operator as fovea-operator is one (an
// OperatorLink and a MapHolder that keeps and acknowledges the bricks, the gaze
// at 120 Hz) on loopback, optionally through a LossyRelay.
//
//   fovea-map-link --experiment gaze|loss|join [--scene living-room] [--path static] [--size 640x480]
//                  [--fps 30] [--budget-mbps 12.5] [--saccades 12] [--dwell-ms 1500] [--loss 0.1]
//                  [--loss-seconds 6] [--join-after 8] [--seed 1] [--source map|frame] [--preset F1]
//                  [--fuse-budget-ms MS]
//
// --fuse-budget-ms sets the map's map.fuse_budget_ms (fusion's time budget,
// pipeline/map/fusion_budget.h; 0, the default: every frame fused).
// --source frame (gaze only) measures today's frame-by-frame stream instead:
// the service foveates each frame (--preset) for the newest gaze, and the
// operator holds the fovea's detail once a frame foveated for the new gaze
// was sent whole (its decoding adds about a millisecond on loopback).
//
// "The operator holds what its gaze needs" is read from the robot's side
// (ServiceStats::Map): a frame planned for that gaze sample or a later one was
// sent, nothing due waited for the budget (bricks_waiting 0), and every version
// sent is acknowledged whole (bricks_in_flight 0): the operator then holds each
// brick at the level the gaze needs, in its newest version (net/brick_cache.h
// never draws a stale or partial one). The acknowledgement's way back is
// included, so the figure is an upper bound by half a round trip.
//
// Experiments:
//  gaze  after a warm-up (the operator fixates the scene's focus until it holds
//        everything), --saccades fixations --dwell-ms apart on a grid of
//        points around the focus, each new: from the operator's first sample of
//        the new fixation to when it holds what that gaze needs; p50 and p99.
//  loss  the link drops --loss of the datagrams both ways, duplicates 1 % and
//        reorders 1 % for --loss-seconds, then recovers: from the recovery to
//        when the operator holds what its gaze needs (its copy is then what a
//        loss-free link would have given it), and the versions lost on the way.
//  join  the service fuses --join-after seconds with nobody there; then the
//        operator says hello, asking for --budget-mbps: from the hello to when it
//        holds what its gaze needs (the whole map seen so far, at the levels the
//        gaze needs), and the points and bytes that took.
// An evaluation tool: it allocates freely and prints its figures.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "bench/bench_input.h"
#include "bench/mock_scene.h"
#include "core/clock.h"
#include "firmware/service.h"
#include "hal/camera.h"
#include "hal/gpio/mock/mock_gpio.h"
#include "net/operator_link.h"
#include "tools/lossy_relay/lossy_relay.h"
#include "tools/operator/map_holder.h"

namespace {

using namespace fovea;
using bench::option;

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())) - 1));
  return v[i];
}

// The operator: gaze at 120 Hz towards `target`, bricks into the holder,
// acknowledgements when due; frame chunks counted.
struct Operator {
  Operator(std::unique_ptr<net::OperatorLink> l, tools::MapHolder h, const Eigen::Vector3d& e)
      : link(std::move(l)), holder(std::move(h)), eye(e) {}
  std::unique_ptr<net::OperatorLink> link;
  tools::MapHolder holder;
  Eigen::Vector3d eye;
  std::atomic<int> target_index{0};
  std::vector<Eigen::Vector3d> targets;
  std::atomic<int64_t> target_stamp_ns{0};  // the stamp of the first sample towards the current target
  std::atomic<bool> stop{false};
  std::atomic<uint64_t> frame_chunks{0}, bytes{0};
  std::thread thread;

  ~Operator() {
    stop.store(true);
    if (thread.joinable()) thread.join();
  }
  void start() {
    thread = std::thread([this] { run(); });
  }
  void run() {
    uint64_t sequence = 0;
    int sent_target = -1;
    int64_t next_gaze = monotonicNs();
    const std::size_t max_payload = link->mtuBytes() - net::kDatagramOverhead;
    while (!stop.load()) {
      const int64_t now = monotonicNs();
      if (now >= next_gaze) {
        const int t = target_index.load();
        const Eigen::Vector3d d = (targets[static_cast<std::size_t>(t)] - eye).normalized();
        const Eigen::Quaterniond head = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), d);
        net::GazeSample g;
        g.sequence = ++sequence;
        g.operator_stamp_ns = now;
        g.gaze_origin_m = {eye.x(), eye.y(), eye.z()};
        g.gaze_direction = {d.x(), d.y(), d.z()};
        g.hmd_position_m = g.gaze_origin_m;
        g.hmd_orientation = {head.w(), head.x(), head.y(), head.z()};
        if (link->sendGaze(g) && t != sent_target) {
          sent_target = t;
          target_stamp_ns.store(now);
        }
        next_gaze += 1'000'000'000 / 120;
      }
      if (std::optional<net::Received> r = link->receive(1)) {
        bytes.fetch_add(r->payload.size() + net::kDatagramOverhead);
        if (r->type == net::MessageType::kBrickChunk) {
          (void)holder.add(r->payload, r->received_ns);
        } else if (r->type == net::MessageType::kChunk) {
          frame_chunks.fetch_add(1);
        }
      }
      if (holder.ackDue(monotonicNs(), max_payload)) {
        holder.sendAcks(max_payload, monotonicNs(), [&](const net::BrickAckMsg& m) { return link->sendBrickAck(m); });
      }
    }
  }
};

struct LinkOptions {
  std::string experiment;
  std::string spec;  // the mock camera's (mock_scene.h), with fps
  int fps = 30;
  double budget_mbps = 12.5;
  int saccades = 12;
  int dwell_ms = 1500;
  double loss = 0.1;
  double loss_seconds = 6;
  double join_after = 8;
  uint64_t seed = 1;
  std::string source = "map";
  std::string preset = "F1";
  double fuse_budget_ms = 0.0;
};

// Returns the options, or nothing after printing the usage.
std::optional<LinkOptions> parseOptions(int argc, char** argv) {
  LinkOptions o;
  o.experiment = option(argc, argv, "--experiment", "");
  o.fps = std::atoi(option(argc, argv, "--fps", "30").c_str());
  o.budget_mbps = std::atof(option(argc, argv, "--budget-mbps", "12.5").c_str());
  o.saccades = std::atoi(option(argc, argv, "--saccades", "12").c_str());
  o.dwell_ms = std::atoi(option(argc, argv, "--dwell-ms", "1500").c_str());
  o.loss = std::atof(option(argc, argv, "--loss", "0.1").c_str());
  o.loss_seconds = std::atof(option(argc, argv, "--loss-seconds", "6").c_str());
  o.join_after = std::atof(option(argc, argv, "--join-after", "8").c_str());
  o.seed = static_cast<uint64_t>(std::atoll(option(argc, argv, "--seed", "1").c_str()));
  o.source = option(argc, argv, "--source", "map");
  o.preset = option(argc, argv, "--preset", "F1");
  o.fuse_budget_ms = std::atof(option(argc, argv, "--fuse-budget-ms", "0").c_str());
  if ((o.experiment != "gaze" && o.experiment != "loss" && o.experiment != "join") || o.fps < 1 ||
      !(o.budget_mbps > 0) || o.saccades < 1 || o.dwell_ms < 100 || !(o.loss >= 0 && o.loss <= 0.5) ||
      !(o.loss_seconds > 0) || !(o.join_after >= 0) || (o.source != "map" && o.source != "frame") ||
      (o.source == "frame" && o.experiment != "gaze") || !pipeline::parsePreset(o.preset) ||
      !(o.fuse_budget_ms >= 0.0)) {
    std::fprintf(stderr,
                 "usage: fovea-map-link --experiment gaze|loss|join [--scene S] [--path P] [--size WxH] [--fps N]\n"
                 "                      [--budget-mbps MBPS] [--saccades N] [--dwell-ms MS] [--loss SHARE]\n"
                 "                      [--loss-seconds S] [--join-after S] [--seed N] [--source map|frame]\n"
                 "                      [--preset NAME] (--source frame: gaze only) [--fuse-budget-ms MS]\n");
    return std::nullopt;
  }
  o.spec = bench::mockSceneSpec(argc, argv, "static") + ",fps=" + std::to_string(o.fps);
  return o;
}

// Where the operator's eye is and what it looks at: the camera's first pose and
// the scene's focus, from a camera of the same spec in this process.
struct View {
  Eigen::Vector3d eye, focus;
  Eigen::Matrix3d camera_axes;
};

int firstView(const std::string& spec, View& view) {
  auto cam = hal::createCamera(spec);
  if (!cam || !cam.value()->open() || !cam.value()->start()) {
    std::fprintf(stderr, "fovea-map-link: %s: the camera did not start\n", spec.c_str());
    return 1;
  }
  hal::RgbdFrame first(cam.value()->info().intrinsics.width, cam.value()->info().intrinsics.height);
  if (!cam.value()->acquire(first, std::chrono::seconds(5))) return 1;
  view.eye = first.T_world_cam.t_world_cam;
  view.camera_axes = first.T_world_cam.R_world_cam;
  view.focus = cam.value()->info().focus_point_m.value_or(view.eye + view.camera_axes.col(2) * 2.5);
  return 0;
}

// The service on the mock camera, foveating from the map (or frame by frame),
// listening on loopback; nullptr after printing why it could not be made.
std::unique_ptr<firmware::Service> createService(const LinkOptions& o) {
  firmware::ServiceConfig config;
  config.camera.spec = o.spec + ",realtime=on";
  if (o.source == "map") {
    config.map.source = firmware::FoveationSource::kMap;
    config.map.delta = true;
    config.map.fuse_budget_ms = o.fuse_budget_ms;
  } else {
    config.foveation.acuity.preset = pipeline::parsePreset(o.preset).value();
  }
  config.stream.link.listen = "127.0.0.1:0";
  config.stream.link.insecure = true;
  config.gpio.lines.heartbeat_line = config.gpio.lines.streaming_line = config.gpio.lines.fault_line =
      config.gpio.lines.privacy_line = firmware::StatusLinesConfig::kNoLine;
  config.runtime.status_interval_ms = 60'000;
  firmware::Service::Environment environment;
  environment.gpio = std::make_unique<hal::mock::MockGpio>(8);
  Result<std::unique_ptr<firmware::Service>> created = firmware::Service::create(config, std::move(environment));
  if (!created) {
    std::fprintf(stderr, "fovea-map-link: %s\n", created.status().message().c_str());
    return nullptr;
  }
  return std::move(created.value());
}

// The service's supervisor thread, asked to stop and joined on destruction.
class Supervisor {
 public:
  explicit Supervisor(firmware::Service& service) : service_(service), thread_([this] { service_.run(); }) {}
  ~Supervisor() {
    service_.requestStop();
    if (thread_.joinable()) thread_.join();
  }
  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

 private:
  firmware::Service& service_;
  std::thread thread_;
};

// The loss experiment's LossyRelay between the operator and the robot, pumped by
// its own thread until destruction; recover() lifts the loss.
class Relay {
 public:
  Relay() = default;
  ~Relay() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  Relay(const Relay&) = delete;
  Relay& operator=(const Relay&) = delete;

  // Starts the relay in front of `robot`; false after printing why it did not.
  bool start(const net::Endpoint& robot, const LinkOptions& o) {
    tools::LossyRelayConfig rc;
    rc.listen = net::Endpoint::parse("127.0.0.1:0").value();
    rc.server = robot;
    rc.up = rc.down = {o.loss, 0.01, 0.01};
    rc.seed = o.seed;
    Result<tools::LossyRelay> r = tools::LossyRelay::create(rc);
    if (!r) {
      std::fprintf(stderr, "fovea-map-link: relay: %s\n", r.status().message().c_str());
      return false;
    }
    relay_ = std::make_unique<tools::LossyRelay>(std::move(r.value()));
    thread_ = std::thread([this] {
      bool recovered = false;
      while (!stop_.load()) {
        if (!recovered && recover_.load()) {
          (void)relay_->setShares({}, {});
          recovered = true;
        }
        relay_->pump(2);
      }
    });
    return true;
  }
  void recover() { recover_.store(true); }
  const tools::LossyRelay& relay() const { return *relay_; }

 private:
  std::unique_ptr<tools::LossyRelay> relay_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> recover_{false};
  std::thread thread_;
};

// Connects the operator to `robot` (hello_ns: when it said hello), its fixations
// the focus and then a grid around it, and starts its thread; nullptr after
// printing why it could not connect.
std::unique_ptr<Operator> connectOperator(const LinkOptions& o, const net::Endpoint& robot, const View& view,
                                          int64_t& hello_ns) {
  net::OperatorLinkConfig op_config;
  op_config.insecure = true;
  op_config.budget_bytes_per_s = static_cast<uint64_t>(o.budget_mbps * 1e6);
  hello_ns = monotonicNs();
  Result<std::unique_ptr<net::OperatorLink>> link = net::OperatorLink::connect(robot.toString(), op_config);
  if (!link) {
    std::fprintf(stderr, "fovea-map-link: connect: %s\n", link.status().message().c_str());
    return nullptr;
  }
  net::BrickCacheConfig cache;
  cache.max_points = std::size_t{1} << 21;
  auto op = std::make_unique<Operator>(std::move(link.value()), tools::MapHolder::create(cache).value(), view.eye);
  // Fixations: the focus, then a grid of points around it (camera-relative
  // offsets, 4 x 3 over 2.4 m x 1.2 m), each new.
  op->targets.push_back(view.focus);
  for (int k = 0; k < o.saccades; ++k) {
    const double u = -1.2 + 0.8 * static_cast<double>(k % 4), v = -0.6 + 0.6 * static_cast<double>((k / 4) % 3);
    op->targets.push_back(view.focus + view.camera_axes * Eigen::Vector3d(u, v, 0.0));
  }
  op->start();
  return op;
}

// What the experiments watch: the service's figures and the operator's.
struct Session {
  const LinkOptions& o;
  firmware::Service& service;
  Operator& op;
  Relay& relay;
  int64_t hello_ns;
  firmware::ServiceStats before_join;

  // Waits up to timeout_s until the robot has sent the fovea of a frame foveated
  // for the gaze whose first sample was stamped `since` (or a later one) and, with
  // `everything`, nothing is waiting nor unacknowledged, else nothing of the
  // fovea's is waiting. Returns the time from `from_ns`, or -1.
  double heldAfter(int64_t since, int64_t from_ns, double timeout_s, bool everything = true) const {
    const int64_t end = monotonicNs() + static_cast<int64_t>(timeout_s * 1e9);
    while (monotonicNs() < end) {
      const firmware::ServiceStats s = service.stats();
      const bool done = everything ? s.map.bricks_waiting == 0 && s.map.bricks_in_flight == 0
                                   : s.map.fovea_bricks_waiting == 0;
      if (s.sent_gaze_stamp_ns >= since && done) return static_cast<double>(monotonicNs() - from_ns) * 1e-6;
      std::this_thread::sleep_for(std::chrono::microseconds(250));
    }
    const firmware::ServiceStats s = service.stats();
    std::printf("  (not held: last frame sent for gaze %s, %llu bricks waiting, %llu of the fovea, %llu versions "
                "in flight)\n",
                s.sent_gaze_stamp_ns >= since ? "this one or later" : "an older one",
                static_cast<unsigned long long>(s.map.bricks_waiting),
                static_cast<unsigned long long>(s.map.fovea_bricks_waiting),
                static_cast<unsigned long long>(s.map.bricks_in_flight));
    return -1.0;
  }
  int64_t waitStamp() const {
    while (op.target_stamp_ns.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return op.target_stamp_ns.load();
  }
};

// gaze: the warm-up, then each saccade: the fovea's detail sent, everything acknowledged.
int runGaze(const Session& x) {
  const LinkOptions& o = x.o;
  const double warm = x.heldAfter(x.waitStamp(), x.hello_ns, 30.0);
  std::printf("  warm-up: the operator held what the first fixation needs after %.0f ms\n", warm);
  std::this_thread::sleep_for(std::chrono::seconds(3));  // the map settles (map.settle_frames) and goes out
  std::vector<double> fovea_latency, all_latency;
  int failed = 0;
  for (int k = 1; k <= o.saccades; ++k) {
    const uint64_t planned_before = x.service.stats().map.bricks_planned;
    x.op.target_stamp_ns.store(0);
    x.op.target_index.store(k);
    const int64_t stamp = x.waitStamp();
    const double fovea_ms = x.heldAfter(stamp, stamp, o.dwell_ms * 1e-3, false);
    const double all_ms = fovea_ms >= 0 && o.source == "map" ? x.heldAfter(stamp, stamp, o.dwell_ms * 1e-3) : fovea_ms;
    const uint64_t planned = x.service.stats().map.bricks_planned - planned_before;
    if (fovea_ms < 0 || all_ms < 0) {
      ++failed;
      std::printf("  saccade %2d: not within the dwell\n", k);
    } else {
      fovea_latency.push_back(fovea_ms);
      all_latency.push_back(all_ms);
      std::printf("  saccade %2d: the fovea's detail sent after %.0f ms; everything it needs acknowledged after %.0f ms "
                  "(%llu bricks planned meanwhile)\n",
                  k, fovea_ms, all_ms, static_cast<unsigned long long>(planned));
    }
    const int64_t dwell_end = stamp + static_cast<int64_t>(o.dwell_ms) * 1'000'000;
    while (monotonicNs() < dwell_end) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  std::printf("  gaze shift to the fovea's detail (the fovea of a frame for the new gaze sent, nothing of the fovea waiting): "
              "p50 %.1f ms, p99 %.1f ms; to everything the gaze needs acknowledged: p50 %.1f ms, p99 %.1f ms; "
              "%zu saccades (%d not within %d ms)\n",
              percentile(fovea_latency, 0.5), percentile(fovea_latency, 0.99), percentile(all_latency, 0.5),
              percentile(all_latency, 0.99), fovea_latency.size(), failed, o.dwell_ms);
  return failed > 0 ? 1 : 0;
}

// loss: --loss-seconds of loss, then none: the time to hold what the gaze needs.
int runLoss(const Session& x) {
  const LinkOptions& o = x.o;
  const int64_t start = monotonicNs();
  std::this_thread::sleep_for(std::chrono::duration<double>(o.loss_seconds));
  const firmware::ServiceStats lossy = x.service.stats();
  x.relay.recover();
  const int64_t recovered_ns = monotonicNs();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the relay's next pump takes the new shares
  // A gaze sample sent after the recovery: the plans from then on.
  const int64_t since = monotonicNs();
  const double ms = x.heldAfter(since, recovered_ns, 10.0);
  const firmware::ServiceStats end = x.service.stats();
  const tools::MapTotals held = x.op.holder.totals();
  const tools::LossyRelay& relay = x.relay.relay();
  std::printf("  %.1f s at %.0f %% loss (1 %% duplicated, 1 %% reordered), then none: dropped up %llu down %llu, "
              "duplicated %llu down\n",
              static_cast<double>(recovered_ns - start) * 1e-9, o.loss * 100,
              static_cast<unsigned long long>(relay.up().dropped), static_cast<unsigned long long>(relay.down().dropped),
              static_cast<unsigned long long>(relay.down().duplicated));
  std::printf("  robot: %llu versions, %llu lost on the way (sent again), %llu parts resent (%llu during the loss)\n",
              static_cast<unsigned long long>(end.map.brick_versions),
              static_cast<unsigned long long>(end.map.brick_versions_lost),
              static_cast<unsigned long long>(end.map.brick_resends),
              static_cast<unsigned long long>(lossy.map.brick_resends));
  std::printf("  operator: %zu bricks, %zu points held; %llu versions completed, %llu duplicate parts, %llu stale\n",
              held.bricks_held, held.points_held, static_cast<unsigned long long>(held.versions),
              static_cast<unsigned long long>(held.duplicate_parts), static_cast<unsigned long long>(held.stale_parts));
  if (ms >= 0) {
    std::printf("  after the loss stopped the operator held what its gaze needs in %.0f ms\n", ms);
    return 0;
  }
  std::printf("  the operator did not hold what its gaze needs within 10 s of the loss stopping\n");
  return 1;
}

// join: from the operator's hello to when it holds what its gaze needs.
int runJoin(const Session& x) {
  const double ms = x.heldAfter(x.waitStamp(), x.hello_ns, 30.0);
  const tools::MapTotals held = x.op.holder.totals();
  std::printf("  the map after %.1f s alone: %llu surfels; the operator joined asking %.1f MB/s\n", x.o.join_after,
              static_cast<unsigned long long>(x.before_join.map.surfels), x.o.budget_mbps);
  if (ms >= 0) {
    std::printf("  it held what its gaze needs (%zu bricks, %zu points) %.0f ms after its hello, %.2f MB received\n",
                held.bricks_held, held.points_held, ms, static_cast<double>(x.op.bytes.load()) * 1e-6);
    return 0;
  }
  std::printf("  it did not hold what its gaze needs within 30 s\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::optional<LinkOptions> parsed = parseOptions(argc, argv);
  if (!parsed) return 2;
  const LinkOptions& o = *parsed;
  View view;
  if (int status = firstView(o.spec, view); status != 0) return status;
  const std::unique_ptr<firmware::Service> service = createService(o);
  if (!service) return 1;
  if (Status s = service->start(); !s) {
    std::fprintf(stderr, "fovea-map-link: %s\n", s.message().c_str());
    return 1;
  }
  const Supervisor supervisor(*service);

  // The link: direct, or through the relay (loss).
  Relay relay;
  net::Endpoint robot = service->localEndpoint();
  if (o.experiment == "loss") {
    if (!relay.start(robot, o)) return 1;
    robot = relay.relay().localEndpoint();
  }

  if (o.experiment == "join") std::this_thread::sleep_for(std::chrono::duration<double>(o.join_after));
  const firmware::ServiceStats before_join = service->stats();
  int64_t hello_ns = 0;
  const std::unique_ptr<Operator> op = connectOperator(o, robot, view, hello_ns);
  if (!op) return 1;

  std::printf("fovea-map-link: %s, %s, %s, budget %.1f MB/s, fusion's time budget %.1f ms\n", o.experiment.c_str(),
              o.spec.c_str(),
              o.source == "map" ? "the map's bricks (foveation.source = map, map.delta)" : ("frame by frame, " + o.preset).c_str(),
              o.budget_mbps, o.fuse_budget_ms);
  const Session session{o, *service, *op, relay, hello_ns, before_join};
  if (o.experiment == "gaze") return runGaze(session);
  if (o.experiment == "loss") return runLoss(session);
  return runJoin(session);
}
