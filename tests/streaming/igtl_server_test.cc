// The OpenIGTLink server with in-process clients on 127.0.0.1: what a client
// receives, the text and status of a correction, ports, and clients that
// connect, leave, or never read. Every wait is bounded.
#include "streaming/igtl_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <future>
#include <thread>

#include <gtest/gtest.h>

#include "streaming/igtl_test_client.h"
#include "util/check.h"

namespace arpos {
namespace {

using Clock = std::chrono::steady_clock;
using testing::IgtlTestClient;
using testing::MatrixMm;
using testing::MessageCount;
using testing::TestFrame;

IgtlServerOptions AnyPort() {
  IgtlServerOptions options;
  options.port = 0;
  return options;
}

// Polls `condition` every few milliseconds for up to `timeout_s`.
bool Eventually(const std::function<bool()>& condition, double timeout_s = 10) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (!condition()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

// A plain TCP client on 127.0.0.1:port that never reads unless told;
// receive_buffer_bytes > 0 shrinks its receive buffer (before connecting).
class RawClient {
 public:
  explicit RawClient(int port, int receive_buffer_bytes = 0) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (receive_buffer_bytes > 0) {
      ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer_bytes, sizeof(receive_buffer_bytes));
    }
    timeval timeout{5, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    ::inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
    connected_ = ::connect(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) == 0;
  }
  ~RawClient() { Close(); }
  bool connected() const { return connected_; }
  void Close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  // Reads until the connection ends (true) or a read times out (false).
  bool ReadsToEnd() {
    char buffer[4096];
    for (;;) {
      const ssize_t n = ::recv(fd_, buffer, sizeof(buffer), 0);
      if (n == 0) return true;
      if (n < 0) return errno == ECONNRESET;
    }
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
};

// Runs `body` on another thread and waits up to `timeout_s` for it. A body
// that does not return is a failure that ends the test program (a hung test
// would hang ctest instead).
void RunWithin(double timeout_s, const std::function<void()>& body) {
  std::packaged_task<void()> task(body);
  std::future<void> done = task.get_future();
  std::thread thread(std::move(task));
  if (done.wait_for(std::chrono::duration<double>(timeout_s)) != std::future_status::ready) {
    std::fprintf(stderr, "FAILED: did not return within %.0f s\n", timeout_s);
    std::fflush(stderr);
    std::_Exit(1);
  }
  thread.join();
  done.get();
}

TEST(IgtlFrame, CorrectionTextHasEveryFieldInItsFormat) {
  CouchCorrection c;
  c.lateral_mm = 1.2;
  c.longitudinal_mm = -0.5;
  c.vertical_mm = -0.0004;  // rounds to zero: no "-0.000"
  c.pitch_deg = 0.1;
  c.roll_deg = -0.2;
  c.yaw_deg = -0.00001;
  c.translation_mm = 1.3;
  c.rotation_deg = 0.2291;
  c.uncertainty = {0.4, 0.1};
  c.state = CorrectionState::kOut;
  EXPECT_EQ(IgtlCorrectionText(c),
            "state=out lateral_mm=+1.200 longitudinal_mm=-0.500 vertical_mm=+0.000 pitch_deg=+0.1000 "
            "roll_deg=-0.2000 yaw_deg=+0.0000 translation_mm=1.300 rotation_deg=0.2291 uncertainty_mm=0.400 "
            "uncertainty_deg=0.1000");
  c.state = CorrectionState::kIn;
  EXPECT_EQ(IgtlCorrectionText(c).rfind("state=in lateral_mm=+1.200 ", 0), 0u);
  EXPECT_EQ(IgtlCorrectionText(LostCorrection()), "state=lost");
}

TEST(IgtlFrame, StatusCodesFollowOpenIgtLink) {
  EXPECT_EQ(IgtlStatusCode(CorrectionState::kIn), 1);    // STATUS_OK
  EXPECT_EQ(IgtlStatusCode(CorrectionState::kOut), 8);   // STATUS_OVERFLOW
  EXPECT_EQ(IgtlStatusCode(CorrectionState::kLost), 4);  // STATUS_NOT_FOUND
  EXPECT_STREQ(IgtlStatusErrorName(CorrectionState::kOut), "OutOfTolerance");
}

TEST(IgtlFrame, PacksOnlyThePosesItHas) {
  IgtlFrame frame = TestFrame(0);
  ASSERT_TRUE(frame.room_from_model && frame.room_from_camera);
  EXPECT_EQ(PackIgtlFrame(frame).messages, 5);
  frame.room_from_model.reset();
  frame.room_from_camera.reset();
  EXPECT_EQ(PackIgtlFrame(frame).messages, 3);
  frame.timestamp_s = -1;
  EXPECT_THROW(PackIgtlFrame(frame), Error);
}

TEST(IgtlServer, PortZeroListensOnAFreePort) {
  IgtlServer server(AnyPort());
  EXPECT_GT(server.port(), 0);
  EXPECT_EQ(server.clients(), 0);
  EXPECT_FALSE(server.WaitForClient(0.05));
}

TEST(IgtlServer, PortInUseIsAnInputErrorNamingThePort) {
  IgtlServer first(AnyPort());
  IgtlServerOptions same;
  same.port = first.port();
  try {
    IgtlServer second(same);
    FAIL() << "a second server listened on port " << same.port;
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("port " + std::to_string(same.port)), std::string::npos) << message;
    EXPECT_NE(message.find("in use"), std::string::npos) << message;
  }
}

TEST(IgtlServer, BadAddressOrPortIsAnInputError) {
  IgtlServerOptions options = AnyPort();
  options.bind_address = "localhost:18944";
  EXPECT_THROW(IgtlServer{options}, InputError);
  options = AnyPort();
  options.port = 70000;
  EXPECT_THROW(IgtlServer{options}, InputError);
}

TEST(IgtlServer, SendWithoutClientsOnlyCounts) {
  IgtlServer server(AnyPort());
  server.Send(TestFrame(0));
  IgtlFrame bad = TestFrame(1);
  bad.timestamp_s = std::nan("");
  EXPECT_THROW(server.Send(bad), Error);  // not counted
  const IgtlServer::Stats stats = server.stats();
  EXPECT_EQ(stats.frames, 1);
  EXPECT_EQ(stats.messages, 0);
  EXPECT_TRUE(stats.latency_ms.empty());
}

// Every message of every frame, by type, device name, time stamp and content;
// transforms in millimetres.
TEST(IgtlServer, ClientReceivesEveryMessageInMillimetres) {
  IgtlServer server(AnyPort());
  IgtlTestClient client;
  ASSERT_TRUE(client.Connect(server.port(), 10));
  ASSERT_TRUE(server.WaitForClient(10));
  EXPECT_EQ(server.clients(), 1);

  int total = 0;
  for (int i = 0; i < 8; ++i) {
    const IgtlFrame frame = TestFrame(i);
    server.Send(frame);
    total += MessageCount(frame);
    std::vector<std::pair<std::string, Rigid3d>> transforms;
    if (frame.room_from_model) transforms.emplace_back("ModelToRoom", *frame.room_from_model);
    transforms.emplace_back("TargetToRoom", frame.room_from_model_target);
    if (frame.room_from_camera) transforms.emplace_back("CameraToRoom", *frame.room_from_camera);

    for (const auto& [name, pose] : transforms) {
      const auto message = client.Receive();
      ASSERT_TRUE(message) << "frame " << i << ": no " << name;
      EXPECT_EQ(message->type, "TRANSFORM");
      EXPECT_EQ(message->device, name) << "frame " << i;
      EXPECT_TRUE(message->crc_ok);
      EXPECT_NEAR(message->timestamp_s, frame.timestamp_s, 1e-6);
      // 32-bit floats: within 1e-4 mm at 1.5 m, 1e-7 in the rotation.
      EXPECT_LT((message->matrix - MatrixMm(pose)).cwiseAbs().maxCoeff(), 2e-4)
          << name << " frame " << i << "\n" << message->matrix << "\nexpected\n" << MatrixMm(pose);
    }
    const auto status = client.Receive();
    ASSERT_TRUE(status);
    EXPECT_EQ(status->type, "STATUS");
    EXPECT_EQ(status->device, "Tolerance");
    EXPECT_EQ(status->status_code, IgtlStatusCode(frame.correction.state));
    EXPECT_EQ(status->error_name, IgtlStatusErrorName(frame.correction.state));
    EXPECT_EQ(status->status_text, DescribeCorrection(frame.correction));
    EXPECT_NEAR(status->timestamp_s, frame.timestamp_s, 1e-6);
    const auto text = client.Receive();
    ASSERT_TRUE(text);
    EXPECT_EQ(text->type, "STRING");
    EXPECT_EQ(text->device, "Correction");
    EXPECT_EQ(text->text, IgtlCorrectionText(frame.correction));
    EXPECT_TRUE(text->crc_ok);
  }
  const IgtlServer::Stats stats = server.stats();
  EXPECT_EQ(stats.frames, 8);
  EXPECT_EQ(stats.messages, total);
  EXPECT_EQ(stats.latency_ms.size(), 8u);
  EXPECT_EQ(stats.dropped_clients, 0);
}

TEST(IgtlServer, CountsClients) {
  IgtlServer server(AnyPort());
  RawClient a(server.port()), b(server.port()), c(server.port());
  ASSERT_TRUE(a.connected() && b.connected() && c.connected());
  EXPECT_TRUE(Eventually([&] { return server.clients() == 3; })) << server.clients();
  EXPECT_EQ(server.stats().accepted_clients, 3);
  server.Send(TestFrame(0));
  EXPECT_EQ(server.stats().messages, 3 * MessageCount(TestFrame(0)));
}

TEST(IgtlServer, ClientThatDisconnectsIsDropped) {
  IgtlServer server(AnyPort());
  RawClient stays(server.port()), leaves(server.port());
  ASSERT_TRUE(Eventually([&] { return server.clients() == 2; }));
  leaves.Close();
  EXPECT_TRUE(Eventually([&] { return server.clients() == 1; })) << server.clients();
  server.Send(TestFrame(0));
  const IgtlServer::Stats stats = server.stats();
  EXPECT_EQ(stats.dropped_clients, 1);
  EXPECT_EQ(stats.stalled_clients, 0);
  EXPECT_EQ(stats.messages, MessageCount(TestFrame(0)));
}

// A client that connects and never reads: Send keeps returning, and once the
// client's buffers are full it is dropped, counted as stalled, and its
// connection ends.
TEST(IgtlServer, ClientThatNeverReadsIsDroppedNotWaitedFor) {
  IgtlServerOptions options = AnyPort();
  options.send_buffer_bytes = 4096;
  IgtlServer server(options);
  RawClient idle(server.port(), 4096);
  ASSERT_TRUE(idle.connected());
  ASSERT_TRUE(server.WaitForClient(10));

  const IgtlFrame frame = TestFrame(0);
  int sent = 0;
  double slowest_ms = 0;
  RunWithin(60, [&] {
    // A few hundred kilobytes at most fill both buffers; the bound is generous.
    while (server.clients() > 0 && sent < 200000) {
      const auto start = Clock::now();
      server.Send(frame);
      slowest_ms = std::max(slowest_ms, std::chrono::duration<double, std::milli>(Clock::now() - start).count());
      ++sent;
    }
  });
  const IgtlServer::Stats stats = server.stats();
  EXPECT_EQ(server.clients(), 0) << "after " << sent << " frames";
  EXPECT_EQ(stats.dropped_clients, 1);
  EXPECT_EQ(stats.stalled_clients, 1);
  EXPECT_EQ(stats.frames, sent);
  std::printf("idle client dropped after %d frames; slowest Send %.3f ms\n", sent, slowest_ms);
  // What the client had buffered, then the end.
  EXPECT_TRUE(idle.ReadsToEnd());
}

TEST(IgtlServer, DestructorEndsClientConnections) {
  auto server = std::make_unique<IgtlServer>(AnyPort());
  RawClient client(server->port());
  ASSERT_TRUE(server->WaitForClient(10));
  server.reset();
  EXPECT_TRUE(client.ReadsToEnd());
}

}  // namespace
}  // namespace arpos
