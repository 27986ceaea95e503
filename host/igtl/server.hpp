#pragma once
// The OpenIGTLink TCP server of arnav-igtl (docs/igtl.md). Any number of clients; each has
// a reader thread (frames what the client sends with igtl::StreamReader, answers
// STT_TDATA/STP_TDATA/GET_STATUS/GET_POLYDATA/STT_POLYDATA/STP_POLYDATA, skips the rest, v1 or v2 headers) and a sender thread
// that keeps only the latest message of each stream (a client slower than the tracker
// misses poses, never delays them for others), sends a STATUS_OK keep-alive when nothing
// else went out for keepalive_s, and drops the client when a send fails or does not
// finish within send_timeout_s. publish() never blocks on a socket.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "host/igtl/messages.hpp"
#include "host/igtl/wire.hpp"

namespace arnav::igtl {

struct ServerOptions {
  std::string bind_address = "127.0.0.1";
  int port = 18944;                 // 0: any free port (tests), see Server::port()
  double keepalive_s = 0.25;
  double send_timeout_s = 2.0;
  std::string status_device_name = "ARNav";
  std::uint64_t max_body_bytes = 1ull << 30;   // a client's message above this: stream lost, client dropped
};

class ServerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ServerStats {
  std::uint64_t clients_accepted = 0;
  std::uint64_t clients_now = 0;
  std::uint64_t clients_dropped = 0;     // send failure or timeout, framing error
  std::uint64_t clients_closed = 0;      // the client closed the connection
  std::uint64_t messages_sent = 0;
  std::uint64_t messages_replaced = 0;   // a newer message of the same stream replaced it before it was sent
  std::uint64_t keepalives_sent = 0;
  std::uint64_t requests_handled = 0;    // STT_TDATA, STP_TDATA, GET_STATUS, GET_POLYDATA, STT_POLYDATA, STP_POLYDATA
  std::uint64_t polydata_unknown = 0;    // GET_POLYDATA for a name with no surface: answered with an empty POLYDATA
  std::uint64_t messages_skipped = 0;    // received messages of types arnav-igtl does not handle
};

class Server {
 public:
  using Log = std::function<void(const std::string&)>;
  // Binds and listens; throws ServerError naming the address and port and what to do.
  Server(ServerOptions options, Log log);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  int port() const { return port_; }
  // Queues `packet` for every client as the latest message of `stream` (e.g. the device name).
  void publish(const std::string& stream, const Packet& packet);
  // Queues `packet` for the clients that asked for tracking data (STT_TDATA).
  void publish_tdata(const std::string& stream, const Packet& packet);
  // A POLYDATA named `device_name`: queued for every client that has not stopped it with
  // STP_POLYDATA (the latest per name, like publish) and kept as the answer to GET_POLYDATA
  // and STT_POLYDATA for that name.
  void publish_polydata(const std::string& device_name, const Packet& packet);
  ServerStats stats() const;
  std::size_t clients() const;
  // Stops accepting, closes every client and joins the threads (also done by the destructor).
  void stop();

 private:
  struct Client;
  void accept_loop();
  void reap_finished();
  void reader_loop(Client& c);
  void sender_loop(Client& c);
  void handle_request(Client& c, const Message& m);
  void answer_get_polydata(Client& c, const std::string& device_name);
  void set_polydata_stream(Client& c, const std::string& device_name, bool start);
  // The latest POLYDATA of that name (every name when empty); `known` gets all names there are.
  std::vector<std::pair<std::string, Packet>> latest_polydata(const std::string& device_name, std::string* known = nullptr);
  // Queues `packet` as the latest of `stream` for each client for which `wants` holds
  // (evaluated under the client's lock).
  void publish_where(const std::string& stream, const Packet& packet, const std::function<bool(const Client&)>& wants);
  void queue(Client& c, const std::string& stream, const Packet& packet);
  bool send_all(Client& c, const Packet& packet);
  void close_client(Client& c, const std::string& why, bool dropped);

  ServerOptions options_;
  Log log_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  mutable std::mutex clients_mutex_;
  std::list<std::unique_ptr<Client>> clients_;
  std::thread accept_thread_;
  mutable std::mutex stats_mutex_;
  ServerStats stats_;
  std::mutex polydata_mutex_;                     // taken before a client's mutex, never inside one
  std::map<std::string, Packet> polydata_;        // device name -> latest POLYDATA
};

}  // namespace arnav::igtl
