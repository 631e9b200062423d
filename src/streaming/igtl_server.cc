#include "streaming/igtl_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <thread>

#include "util/check.h"

namespace arpos {

namespace {

using Clock = std::chrono::steady_clock;

std::string ErrnoText(int error) { return std::strerror(error); }

void CloseFd(int* fd) {
  if (*fd >= 0) ::close(*fd);
  *fd = -1;
}

// Options every client socket gets: no Nagle delay (one small write per
// frame), and a bounded send buffer.
void ConfigureClientSocket(int fd, int send_buffer_bytes) {
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  if (send_buffer_bytes > 0) {
    ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &send_buffer_bytes, sizeof(send_buffer_bytes));
  }
}

}  // namespace

struct IgtlServer::Impl {
  struct Client {
    int fd = -1;
    /// Given up on by Send (shut down, counted); the I/O thread closes it.
    bool dropped = false;
  };

  IgtlServerOptions options;
  int listen_fd = -1;
  int wake_read = -1, wake_write = -1;  ///< a pipe that interrupts the I/O thread's poll
  int port = 0;

  mutable std::mutex mutex;
  std::condition_variable client_joined;
  std::vector<Client> clients;  ///< only the I/O thread adds, closes and erases
  int live_clients = 0;         ///< clients not dropped
  bool stopping = false;
  Stats stats;
  std::thread io_thread;

  void Listen();
  void Wake();
  void RunIo();
  void AcceptAll();
  // Reads and discards what the client sent; false when it has closed or failed.
  bool Drain(int fd);
  // Gives up on a client (under the lock): counted, shut down so the I/O
  // thread sees it and closes it.
  void Drop(Client* client, bool stalled);
  void CloseAll();
};

void IgtlServer::Impl::Listen() {
  const std::string where = "OpenIGTLink server on " + options.bind_address + " port " +
                            std::to_string(options.port);
  if (options.port < 0 || options.port > 65535) {
    ARPOS_INPUT_ERROR("Cannot start the " << where << ": the port must be 0 to 65535 (0: any free port).");
  }
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(options.port));
  if (::inet_pton(AF_INET, options.bind_address.c_str(), &address.sin_addr) != 1) {
    ARPOS_INPUT_ERROR("Cannot start the " << where << ": '" << options.bind_address
                                          << "' is not an IPv4 address (127.0.0.1: this computer only, "
                                             "0.0.0.0: every interface).");
  }

  listen_fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  ARPOS_CHECK(listen_fd >= 0, "socket() for the " << where << " failed: " << ErrnoText(errno));
  // A restarted server may take the port while old connections linger in
  // TIME_WAIT; a port another socket listens on is still refused.
  int one = 1;
  ::setsockopt(listen_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (::bind(listen_fd, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0 ||
      ::listen(listen_fd, 8) != 0) {
    const int error = errno;
    CloseFd(&listen_fd);
    if (error == EADDRINUSE) {
      ARPOS_INPUT_ERROR("Cannot start the " << where << ": the port is in use (another OpenIGTLink server, "
                                               "e.g. PLUS or a second ARPos, may hold it); choose another port.");
    }
    ARPOS_INPUT_ERROR("Cannot start the " << where << ": " << ErrnoText(error) << ".");
  }
  sockaddr_in bound{};
  socklen_t length = sizeof(bound);
  ARPOS_CHECK(::getsockname(listen_fd, reinterpret_cast<sockaddr*>(&bound), &length) == 0,
              "getsockname for the " << where << " failed: " << ErrnoText(errno));
  port = ntohs(bound.sin_port);

  int pipe_fds[2];
  ARPOS_CHECK(::pipe2(pipe_fds, O_CLOEXEC | O_NONBLOCK) == 0, "pipe2 failed: " << ErrnoText(errno));
  wake_read = pipe_fds[0];
  wake_write = pipe_fds[1];
}

void IgtlServer::Impl::Wake() {
  const char byte = 1;
  // A full pipe already wakes the thread: nothing to do if this fails.
  [[maybe_unused]] const ssize_t n = ::write(wake_write, &byte, 1);
}

void IgtlServer::Impl::RunIo() {
  std::vector<pollfd> fds;
  for (;;) {
    fds.clear();
    fds.push_back({wake_read, POLLIN, 0});
    fds.push_back({listen_fd, POLLIN, 0});
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (stopping) return;
      for (const Client& client : clients) fds.push_back({client.fd, POLLIN, 0});
    }
    // The timeout is a safety net only: every change wakes the poll.
    if (::poll(fds.data(), fds.size(), 1000) < 0 && errno != EINTR) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (fds[0].revents != 0) {
      char buffer[64];
      while (::read(wake_read, buffer, sizeof(buffer)) > 0) {
      }
    }

    std::lock_guard<std::mutex> lock(mutex);
    if (stopping) return;
    if (fds[1].revents != 0) AcceptAll();
    // Clients polled this round that have data or ended. The fds are still
    // theirs: only this thread closes client sockets.
    for (std::size_t i = 2; i < fds.size(); ++i) {
      if (fds[i].revents == 0) continue;
      auto it = std::find_if(clients.begin(), clients.end(), [&](const Client& c) { return c.fd == fds[i].fd; });
      if (it == clients.end() || it->dropped) continue;
      if (!Drain(it->fd)) {
        it->dropped = true;
        --live_clients;
        ++stats.dropped_clients;
      }
    }
    // Close every client given up on, here or by Send.
    for (Client& client : clients) {
      if (client.dropped) CloseFd(&client.fd);
    }
    clients.erase(std::remove_if(clients.begin(), clients.end(), [](const Client& c) { return c.fd < 0; }),
                  clients.end());
  }
}

void IgtlServer::Impl::AcceptAll() {
  for (;;) {
    const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;  // EAGAIN: no more; other errors: the next poll retries
    ConfigureClientSocket(fd, options.send_buffer_bytes);
    clients.push_back({fd, false});
    ++live_clients;
    ++stats.accepted_clients;
    client_joined.notify_all();
  }
}

bool IgtlServer::Impl::Drain(int fd) {
  char buffer[4096];
  // Bounded: a client that floods us cannot hold the lock.
  for (int reads = 0; reads < 64; ++reads) {
    const ssize_t n = ::recv(fd, buffer, sizeof(buffer), MSG_DONTWAIT);
    if (n > 0) continue;
    if (n == 0) return false;  // closed by the client
    if (errno == EINTR) continue;
    return errno == EAGAIN || errno == EWOULDBLOCK;
  }
  return true;
}

void IgtlServer::Impl::Drop(Client* client, bool stalled) {
  client->dropped = true;
  --live_clients;
  ++stats.dropped_clients;
  if (stalled) ++stats.stalled_clients;
  ::shutdown(client->fd, SHUT_RDWR);
}

void IgtlServer::Impl::CloseAll() {
  for (Client& client : clients) CloseFd(&client.fd);
  clients.clear();
  live_clients = 0;
  CloseFd(&listen_fd);
  CloseFd(&wake_read);
  CloseFd(&wake_write);
}

IgtlServer::IgtlServer(const IgtlServerOptions& options) : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  // OpenIGTLink creates its object factory on first use, unguarded: do it
  // here, on the constructing thread, before Send may run on another.
  PackIgtlFrame(IgtlFrame{});
  try {
    impl_->Listen();
  } catch (...) {
    impl_->CloseAll();
    throw;
  }
  impl_->io_thread = std::thread([impl = impl_.get()] { impl->RunIo(); });
}

IgtlServer::~IgtlServer() {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->stopping = true;
  }
  impl_->client_joined.notify_all();
  impl_->Wake();
  if (impl_->io_thread.joinable()) impl_->io_thread.join();
  impl_->CloseAll();
}

int IgtlServer::port() const { return impl_->port; }

int IgtlServer::clients() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->live_clients;
}

bool IgtlServer::WaitForClient(double timeout_s) {
  // Capped so that the deadline cannot overflow the clock (about 11 days).
  const double wait_s = std::isnan(timeout_s) ? 0.0 : std::clamp(timeout_s, 0.0, 1e6);
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(wait_s));
  std::unique_lock<std::mutex> lock(impl_->mutex);
  return impl_->client_joined.wait_until(lock, deadline,
                                         [&] { return impl_->live_clients > 0 || impl_->stopping; }) &&
         impl_->live_clients > 0;
}

void IgtlServer::Send(const IgtlFrame& frame) {
  const Clock::time_point start = Clock::now();
  // Packed outside the lock, with or without clients (tens of microseconds);
  // checks the timestamp before anything is counted or sent.
  const IgtlPackedFrame packed = PackIgtlFrame(frame);

  bool dropped_any = false;
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    ++impl_->stats.frames;
    bool delivered = false;
    for (Impl::Client& client : impl_->clients) {
      if (client.dropped) continue;
      ssize_t n;
      do {
        n = ::send(client.fd, packed.bytes.data(), packed.bytes.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      } while (n < 0 && errno == EINTR);
      if (n == static_cast<ssize_t>(packed.bytes.size())) {
        delivered = true;
        impl_->stats.messages += packed.messages;
        continue;
      }
      // Part of a frame, or none of it: either way the client's stream can
      // only continue with a frame it cannot take, so it ends here.
      const bool stalled = n >= 0 || errno == EAGAIN || errno == EWOULDBLOCK;
      impl_->Drop(&client, stalled);
      dropped_any = true;
    }
    if (delivered) {
      const Clock::time_point from = frame.arrival == Clock::time_point{} ? start : frame.arrival;
      impl_->stats.latency_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - from).count());
    }
  }
  if (dropped_any) impl_->Wake();
}

IgtlServer::Stats IgtlServer::stats() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->stats;
}

}  // namespace arpos
