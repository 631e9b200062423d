// Latency of the OpenIGTLink stream, per frame (the goal: messages
// within 5 ms of the correction):
//
//   igtl_bench [--benchmark_filter=...]
//
// An IgtlServer on 127.0.0.1 (any free port) and 1 or 4 clients in this
// process, each an igtl::ClientSocket on its own thread that reads and
// decodes every message (CRC checked) as a client would. Each iteration is
// one frame (5 messages, or fewer for a lost frame: the made-up stream of
// the tests) handed to Send with `arrival` = now; it ends when every client
// has decoded the frame's last message. Frames go back to back, or one every
// 33 ms (30 fps, the clients idle between frames as in a real run).
//
// Time is manual: arrival to the last client's last message decoded.
// Counters, per frame (mean, then p95 and max):
//   received_ms, p95_received_ms, max_received_ms   arrival -> decoded by every client
//   send_ms, p95_send_ms, max_send_ms               IgtlServer::Send's own time
//   server_ms, p95_server_ms, max_server_ms         the server's Stats::latency_ms
//                                                   (arrival -> last byte to the sockets)
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>

#include "eval/trajectory_eval.h"
#include "streaming/igtl_server.h"
#include "streaming/igtl_test_client.h"

namespace arpos {
namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

// A client on its own thread noting when it has decoded each frame's last
// message (the STRING "Correction").
class TimedClient {
 public:
  bool Start(int port) {
    if (!client_.Connect(port, 5)) return false;
    thread_ = std::thread([this] { Run(); });
    return true;
  }
  ~TimedClient() {
    if (thread_.joinable()) thread_.join();  // ends when the server closes
  }
  // When frame `index` was decoded, or nothing after 5 s.
  std::optional<Clock::time_point> WaitFor(std::size_t index) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (!done_.wait_for(lock, std::chrono::seconds(5), [&] { return decoded_.size() > index || ended_; }) ||
        decoded_.size() <= index) {
      return std::nullopt;
    }
    return decoded_[index];
  }

 private:
  void Run() {
    while (const auto message = client_.Receive()) {
      if (message->type != "STRING" || message->device != kIgtlCorrectionString) continue;
      const Clock::time_point now = Clock::now();
      std::lock_guard<std::mutex> lock(mutex_);
      decoded_.push_back(now);
      done_.notify_all();
    }
    std::lock_guard<std::mutex> lock(mutex_);
    ended_ = true;
    done_.notify_all();
  }

  testing::IgtlTestClient client_;
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable done_;
  std::vector<Clock::time_point> decoded_;
  bool ended_ = false;
};

void SetCounters(benchmark::State& state, const std::string& name, const std::vector<double>& values_ms) {
  const ErrorStats stats = ComputeErrorStats(values_ms);
  state.counters[name + "_ms"] = stats.mean;
  state.counters["p95_" + name + "_ms"] = stats.p95;
  state.counters["max_" + name + "_ms"] = stats.max;
}

// range(0): milliseconds between frames; range(1): clients.
void BM_IgtlLatency(benchmark::State& state) {
  const auto interval = std::chrono::milliseconds(state.range(0));
  const int client_count = static_cast<int>(state.range(1));
  IgtlServerOptions options;
  options.port = 0;
  auto server = std::make_unique<IgtlServer>(options);
  std::vector<std::unique_ptr<TimedClient>> clients;
  for (int c = 0; c < client_count; ++c) {
    clients.push_back(std::make_unique<TimedClient>());
    if (!clients.back()->Start(server->port())) {
      state.SkipWithError("a client could not connect");
      return;
    }
  }
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (server->clients() < client_count && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  std::vector<IgtlFrame> frames;
  for (int i = 0; i < 12; ++i) frames.push_back(testing::TestFrame(i));

  std::vector<double> received_ms, send_ms;
  std::size_t index = 0;
  for (auto _ : state) {
    IgtlFrame frame = frames[index % frames.size()];
    frame.arrival = Clock::now();
    server->Send(frame);
    send_ms.push_back(Ms(Clock::now() - frame.arrival));
    Clock::time_point last = frame.arrival;
    for (const auto& client : clients) {
      const auto decoded = client->WaitFor(index);
      if (!decoded) {
        state.SkipWithError("a client did not receive a frame within 5 s");
        break;
      }
      last = std::max(last, *decoded);
    }
    const double ms = Ms(last - frame.arrival);
    received_ms.push_back(ms);
    state.SetIterationTime(ms / 1000.0);
    ++index;
    if (interval.count() > 0) std::this_thread::sleep_for(interval);
  }
  const IgtlServer::Stats stats = server->stats();
  server.reset();  // the clients' threads end with the connection
  clients.clear();
  if (received_ms.empty()) return;
  SetCounters(state, "received", received_ms);
  SetCounters(state, "send", send_ms);
  SetCounters(state, "server", stats.latency_ms);
  state.counters["dropped_clients"] = static_cast<double>(stats.dropped_clients);
}

BENCHMARK(BM_IgtlLatency)
    ->ArgNames({"interval_ms", "clients"})
    ->Args({0, 1})
    ->Args({33, 1})
    ->Args({0, 4})
    ->Args({33, 4})
    ->Iterations(300)
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace arpos

BENCHMARK_MAIN();
