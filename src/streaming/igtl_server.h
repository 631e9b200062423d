#pragma once
/// An OpenIGTLink server streaming tracking results to any number of clients
/// (3D Slicer's OpenIGTLinkIF in client mode, PLUS, igtl examples): see
/// igtl_frame.h for the messages of a frame.
///
/// - The server listens on construction and accepts clients on its own
///   thread; it reads and discards whatever clients send (OpenIGTLink clients
///   may send their own messages), and notices clients that close.
/// - Send never waits for a client: every client socket is non-blocking, and
///   a client that cannot take a whole frame at once (it does not read, its
///   socket buffer is full) or whose connection failed is dropped and
///   counted. The buffers hold a few seconds of frames at 30 fps (a frame
///   is about 800 bytes; with the default `send_buffer_bytes` a client that
///   never reads goes after some 200 frames on Linux): a client further
///   behind would show a stale pose, so it is dropped instead, and may
///   reconnect.
/// - Sockets are plain POSIX (IPv4, TCP_NODELAY, close-on-exec); OpenIGTLink
///   packs the messages. igtl::ServerSocket is not used: it always binds every
///   interface (INADDR_ANY) and its Send blocks.
/// - No authentication or encryption (OpenIGTLink has none): bind every
///   interface (0.0.0.0) only on the treatment room's network.
///
/// All methods are thread-safe. Free of OpenIGTLink headers (pimpl).

#include <memory>
#include <string>
#include <vector>

#include "streaming/igtl_frame.h"

namespace arpos {

struct IgtlServerOptions {
  /// TCP port; 18944 is OpenIGTLink's (and Slicer's) default. 0: any free
  /// port, see IgtlServer::port().
  int port = 18944;
  /// An IPv4 address of this computer to listen on: "127.0.0.1" (the
  /// default: clients on this computer only) or "0.0.0.0" (every interface,
  /// e.g. Slicer on another workstation).
  std::string bind_address = "127.0.0.1";
  /// Each client socket's send buffer (SO_SNDBUF; Linux doubles it). A
  /// client further behind than this is dropped. <= 0: the system's default.
  int send_buffer_bytes = 64 * 1024;
};

class IgtlServer {
 public:
  /// Creates, binds and listens, and starts accepting clients. Throws
  /// arpos::InputError naming the address and port if it cannot listen (the
  /// port is in use, a bad address or port number).
  explicit IgtlServer(const IgtlServerOptions& options);
  /// Stops accepting and closes every client (they see the connection end).
  ~IgtlServer();
  IgtlServer(const IgtlServer&) = delete;
  IgtlServer& operator=(const IgtlServer&) = delete;

  /// The port listened on (the one chosen when the options said 0).
  int port() const;
  /// Clients connected now.
  int clients() const;
  /// Waits up to `timeout_s` (<= 0: not at all) until at least one client is
  /// connected; true if one is.
  bool WaitForClient(double timeout_s);

  /// Sends the frame's messages to every connected client; returns at once
  /// (see above: slow or gone clients are dropped, never waited for). With no
  /// client the frame is only counted. Throws arpos::Error for a negative or
  /// non-finite timestamp, before anything is counted or sent.
  void Send(const IgtlFrame& frame);

  struct Stats {
    long frames = 0;           ///< Send calls
    long messages = 0;         ///< messages handed to client sockets, summed over clients
    long accepted_clients = 0; ///< connections accepted
    /// Connections that ended while the server ran: closed by the client, a
    /// failed send, or stalled. Not those closed by the destructor.
    long dropped_clients = 0;
    long stalled_clients = 0;  ///< of those, dropped because their socket buffer was full
    /// Per frame that reached at least one client: milliseconds from
    /// frame.arrival to the frame's last byte handed to the last client's
    /// socket. Grows by one double per frame (about 1 MB per hour at 30 fps).
    std::vector<double> latency_ms;
  };
  Stats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arpos
