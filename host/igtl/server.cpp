#include "host/igtl/server.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>
#include <utility>

#include <igtlStatusMessage.h>

#include "protocol/clock.hpp"

namespace arnav::igtl {

struct Server::Client {
  int fd = -1;
  std::string peer;
  std::mutex mutex;
  std::condition_variable wake;
  std::vector<std::pair<std::string, Packet>> pending;  // latest per stream, oldest stream first
  bool tdata = false;
  // POLYDATA pushed to this client: per name (STT_/STP_POLYDATA with a name), else the
  // default (STT_/STP_POLYDATA without one; every surface until the client says otherwise).
  bool polydata_default = true;
  std::map<std::string, bool> polydata_by_name;
  bool wants_polydata(const std::string& name) const {
    const auto it = polydata_by_name.find(name);
    return it != polydata_by_name.end() ? it->second : polydata_default;
  }
  bool closing = false;
  bool sending = false;                // the sender thread has a batch on the way (not under the lock)
  std::int64_t last_sent_mono_us = 0;  // guarded by mutex
  std::atomic<int> threads_running{2};
  std::thread reader;
  std::thread sender;
};

namespace {

std::string errno_text() { return std::strerror(errno); }

// The rest of a message the fast path could send only in part: never replaced by a newer
// message (that would cut a message in the middle of the stream).
const std::string kPartialStream = std::string("\0partial", 8);

timeval to_timeval(double s) {
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(s);
  tv.tv_usec = static_cast<suseconds_t>((s - static_cast<double>(tv.tv_sec)) * 1e6);
  return tv;
}

}  // namespace

Server::Server(ServerOptions options, Log log) : options_(std::move(options)), log_(std::move(log)) {
  const std::string where = options_.bind_address + ":" + std::to_string(options_.port);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(options_.port));
  if (options_.port < 0 || options_.port > 65535)
    throw ServerError("port " + std::to_string(options_.port) + " is not a TCP port: use 0..65535 (OpenIGTLink's is 18944)");
  if (inet_pton(AF_INET, options_.bind_address.c_str(), &addr.sin_addr) != 1)
    throw ServerError("bind address '" + options_.bind_address + "' is not an IPv4 address: use e.g. 127.0.0.1 or 0.0.0.0");
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw ServerError("cannot create a TCP socket: " + errno_text());
  const int yes = 1;
  ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  if (::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd_, 64) != 0) {
    const int error = errno;
    const std::string why = errno_text();
    ::close(listen_fd_);
    throw ServerError("cannot listen on " + where + ": " + why +
                      (error == EADDRINUSE ? " (another OpenIGTLink server, e.g. PlusServer, holds the port: choose another with --port)"
                                           : " (check that --bind names an address of this machine)"));
  }
  socklen_t len = sizeof addr;
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = ntohs(addr.sin_port);
  accept_thread_ = std::thread([this] { accept_loop(); });
}

Server::~Server() { stop(); }

void Server::stop() {
  if (stopping_.exchange(true)) return;
  if (accept_thread_.joinable()) accept_thread_.join();
  std::list<std::unique_ptr<Client>> all;
  {
    std::lock_guard lock(clients_mutex_);
    all.swap(clients_);
  }
  for (auto& c : all) {
    {
      std::lock_guard lock(c->mutex);
      c->closing = true;
    }
    c->wake.notify_all();
    ::shutdown(c->fd, SHUT_RDWR);
  }
  for (auto& c : all) {
    c->reader.join();
    c->sender.join();
    ::close(c->fd);
  }
  if (listen_fd_ >= 0) ::close(listen_fd_);
  listen_fd_ = -1;
}

void Server::accept_loop() {
  while (!stopping_.load()) {
    reap_finished();
    pollfd p{listen_fd_, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    sockaddr_in peer{};
    socklen_t len = sizeof peer;
    const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_CLOEXEC);
    if (fd < 0) continue;
    const int yes = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    const timeval tv = to_timeval(options_.send_timeout_s);
    ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    char ip[INET_ADDRSTRLEN] = {};
    ::inet_ntop(AF_INET, &peer.sin_addr, ip, sizeof ip);
    auto client = std::make_unique<Client>();
    client->fd = fd;
    client->peer = std::string(ip) + ":" + std::to_string(ntohs(peer.sin_port));
    client->last_sent_mono_us = monotonic_us();
    Client& c = *client;
    {
      std::lock_guard lock(clients_mutex_);
      clients_.push_back(std::move(client));
    }
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.clients_accepted;
    }
    log_("client " + c.peer + " connected");
    c.reader = std::thread([this, &c] { reader_loop(c); });
    c.sender = std::thread([this, &c] { sender_loop(c); });
  }
}

void Server::reap_finished() {
  std::list<std::unique_ptr<Client>> done;
  {
    std::lock_guard lock(clients_mutex_);
    for (auto it = clients_.begin(); it != clients_.end();) {
      if ((*it)->threads_running.load() == 0) {
        done.push_back(std::move(*it));
        it = clients_.erase(it);
      } else {
        ++it;
      }
    }
  }
  for (auto& c : done) {
    c->reader.join();
    c->sender.join();
    ::close(c->fd);
  }
}

void Server::close_client(Client& c, const std::string& why, bool dropped) {
  {
    std::lock_guard lock(c.mutex);
    if (c.closing) return;
    c.closing = true;
  }
  c.wake.notify_all();
  ::shutdown(c.fd, SHUT_RDWR);
  {
    std::lock_guard lock(stats_mutex_);
    ++(dropped ? stats_.clients_dropped : stats_.clients_closed);
  }
  log_("client " + c.peer + (dropped ? " dropped: " : " closed: ") + why);
}

void Server::reader_loop(Client& c) {
  StreamReader reader({"STT_TDATA", "STP_TDATA", "GET_STATUS", "GET_POLYDATA", "STT_POLYDATA", "STP_POLYDATA"}, 4096, options_.max_body_bytes);
  std::vector<std::uint8_t> buffer(64 * 1024);
  for (;;) {
    {
      std::lock_guard lock(c.mutex);
      if (c.closing) break;
    }
    pollfd p{c.fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, 200);
    if (ready == 0) continue;
    const ssize_t n = ready < 0 ? -1 : ::recv(c.fd, buffer.data(), buffer.size(), 0);
    if (n == 0) {
      close_client(c, "connection closed by the client", false);
      break;
    }
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      close_client(c, "receive failed: " + errno_text(), true);
      break;
    }
    reader.feed(std::span<const std::uint8_t>(buffer.data(), static_cast<std::size_t>(n)));
    while (auto m = reader.next()) handle_request(c, *m);
    if (reader.failed()) {
      close_client(c, "its stream is not OpenIGTLink: " + reader.error(), true);
      break;
    }
  }
  c.threads_running.fetch_sub(1);
}

void Server::handle_request(Client& c, const Message& m) {
  if (!m.body_kept) {
    std::lock_guard lock(stats_mutex_);
    ++stats_.messages_skipped;
    return;
  }
  if (body_crc(m.body) != m.header.crc) {
    log_("client " + c.peer + ": " + m.header.type + " with a wrong CRC ignored");
    return;
  }
  if (m.header.type == "STT_TDATA" || m.header.type == "STP_TDATA") {
    const bool start = m.header.type == "STT_TDATA";
    bool changed = false;
    {
      std::lock_guard lock(c.mutex);
      changed = c.tdata != start;
      c.tdata = start;
      if (!start)  // no TDATA after the stop: drop one still queued
        c.pending.erase(std::remove_if(c.pending.begin(), c.pending.end(), [](const auto& p) { return p.first.rfind("TDATA:", 0) == 0; }),
                        c.pending.end());
    }
    if (changed) log_("client " + c.peer + (start ? " started" : " stopped") + " tracking data");
  } else if (m.header.type == "GET_STATUS") {
    queue(c, "STATUS", pack_status(options_.status_device_name, ::igtl::StatusMessage::STATUS_OK, "", wall_us()));
  } else if (m.header.type == "GET_POLYDATA") {
    answer_get_polydata(c, m.header.device_name);
  } else if (m.header.type == "STT_POLYDATA" || m.header.type == "STP_POLYDATA") {
    set_polydata_stream(c, m.header.device_name, m.header.type == "STT_POLYDATA");
  }
  std::lock_guard lock(stats_mutex_);
  ++stats_.requests_handled;
}

// GET_POLYDATA (OpenIGTLink "Query Message"): the latest POLYDATA of that name; without a
// name every surface there is; data not available: a POLYDATA of that name with an empty body.
void Server::answer_get_polydata(Client& c, const std::string& device_name) {
  std::string known;
  std::vector<std::pair<std::string, Packet>> answers = latest_polydata(device_name, &known);
  if (answers.empty()) {
    log_("client " + c.peer + ": GET_POLYDATA '" + device_name + "': no such surface (" + (known.empty() ? "none yet" : "have " + known) +
         "): answered with an empty POLYDATA");
    answers.emplace_back(device_name, pack_empty("POLYDATA", device_name, wall_us()));
    std::lock_guard lock(stats_mutex_);
    ++stats_.polydata_unknown;
  }
  for (const auto& [name, packet] : answers) queue(c, "POLYDATA:" + name, packet);
}

// STT_POLYDATA / STP_POLYDATA (OpenIGTLink v2): start or stop pushing the surface of that
// name to this client (every surface without a name), answered with RTS_POLYDATA (status 0).
// A start sends the latest of the surfaces it turns on at once.
void Server::set_polydata_stream(Client& c, const std::string& device_name, bool start) {
  {
    std::lock_guard lock(c.mutex);
    if (device_name.empty()) {
      c.polydata_default = start;
      c.polydata_by_name.clear();
    } else {
      c.polydata_by_name[device_name] = start;
    }
    if (!start)  // nothing of a stopped surface after the answer: drop one still queued
      c.pending.erase(std::remove_if(c.pending.begin(), c.pending.end(),
                                     [&](const auto& p) {
                                       return p.first.rfind("POLYDATA:", 0) == 0 && (device_name.empty() || p.first == "POLYDATA:" + device_name);
                                     }),
                      c.pending.end());
  }
  log_("client " + c.peer + (start ? " started" : " stopped") + " surfaces (" + (device_name.empty() ? "all" : device_name) + ")");
  queue(c, "RTS_POLYDATA", pack_rts("RTS_POLYDATA", device_name, 0, wall_us()));
  if (!start) return;
  for (const auto& [name, packet] : latest_polydata(device_name)) queue(c, "POLYDATA:" + name, packet);
}

std::vector<std::pair<std::string, Packet>> Server::latest_polydata(const std::string& device_name, std::string* known) {
  std::vector<std::pair<std::string, Packet>> latest;
  std::lock_guard lock(polydata_mutex_);
  for (const auto& [name, packet] : polydata_) {
    if (device_name.empty() || name == device_name) latest.emplace_back(name, packet);
    if (known) *known += (known->empty() ? "" : ", ") + name;
  }
  return latest;
}

void Server::publish_polydata(const std::string& device_name, const Packet& packet) {
  {
    std::lock_guard lock(polydata_mutex_);
    polydata_[device_name] = packet;
  }
  publish_where("POLYDATA:" + device_name, packet, [&](const Client& c) { return c.wants_polydata(device_name); });
}

// Fast path: with nothing queued and the sender idle, the caller (the LCM thread) sends at
// once without blocking (MSG_DONTWAIT), saving the sender thread's wake-up; what the socket
// does not take goes to the sender thread, which may block up to the send timeout.
void Server::queue(Client& c, const std::string& stream, const Packet& packet) {
  bool replaced = false, sent_now = false;
  std::string failure;
  {
    std::lock_guard lock(c.mutex);
    if (c.closing) return;
    if (!c.sending && c.pending.empty()) {
      const ssize_t n = ::send(c.fd, packet->data(), packet->size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n == static_cast<ssize_t>(packet->size())) {
        sent_now = true;
        c.last_sent_mono_us = monotonic_us();
      } else if (n > 0) {
        c.pending.emplace_back(kPartialStream, std::make_shared<const std::vector<std::uint8_t>>(packet->begin() + n, packet->end()));
      } else if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
        failure = "send failed: " + errno_text();
      } else {
        c.pending.emplace_back(stream, packet);
      }
    } else {
      auto it = std::find_if(c.pending.begin(), c.pending.end(), [&](const auto& p) { return p.first == stream; });
      if (it != c.pending.end()) {
        it->second = packet;
        replaced = true;
      } else {
        c.pending.emplace_back(stream, packet);
      }
    }
  }
  if (!failure.empty()) {
    close_client(c, failure, true);
    return;
  }
  if (!sent_now) c.wake.notify_one();
  if (replaced || sent_now) {
    std::lock_guard lock(stats_mutex_);
    ++(replaced ? stats_.messages_replaced : stats_.messages_sent);
  }
}

void Server::publish(const std::string& stream, const Packet& packet) {
  std::lock_guard lock(clients_mutex_);
  for (auto& c : clients_) queue(*c, stream, packet);
}

void Server::publish_tdata(const std::string& stream, const Packet& packet) {
  publish_where("TDATA:" + stream, packet, [](const Client& c) { return c.tdata; });
}

void Server::publish_where(const std::string& stream, const Packet& packet, const std::function<bool(const Client&)>& wants) {
  std::lock_guard lock(clients_mutex_);
  for (auto& c : clients_) {
    bool wanted = false;
    {
      std::lock_guard client_lock(c->mutex);
      wanted = wants(*c);
    }
    if (wanted) queue(*c, stream, packet);
  }
}

bool Server::send_all(Client& c, const Packet& packet) {
  const std::uint8_t* p = packet->data();
  std::size_t left = packet->size();
  while (left > 0) {
    const ssize_t n = ::send(c.fd, p, left, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      close_client(c, errno == EAGAIN || errno == EWOULDBLOCK
                          ? "a send did not finish within " + std::to_string(options_.send_timeout_s) + " s (client not reading)"
                          : "send failed: " + errno_text(),
                   true);
      return false;
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  return true;
}

void Server::sender_loop(Client& c) {
  const auto keepalive = std::chrono::microseconds(static_cast<std::int64_t>(options_.keepalive_s * 1e6));
  std::vector<std::pair<std::string, Packet>> batch;
  for (;;) {
    bool keepalive_due = false;
    {
      std::unique_lock lock(c.mutex);
      c.sending = false;
      c.wake.wait_for(lock, keepalive, [&] { return c.closing || !c.pending.empty(); });
      if (c.closing) break;
      batch.swap(c.pending);
      keepalive_due = batch.empty() && monotonic_us() - c.last_sent_mono_us >= static_cast<std::int64_t>(keepalive.count());
      if (batch.empty() && !keepalive_due) continue;
      c.sending = true;
    }
    if (keepalive_due) batch.emplace_back("STATUS", pack_status(options_.status_device_name, ::igtl::StatusMessage::STATUS_OK, "", wall_us()));
    std::uint64_t sent = 0;
    bool ok = true;
    for (const auto& item : batch) {
      if (!(ok = send_all(c, item.second))) break;
      ++sent;
    }
    batch.clear();
    if (sent > 0) {
      std::lock_guard lock(c.mutex);
      c.last_sent_mono_us = monotonic_us();
    }
    {
      std::lock_guard lock(stats_mutex_);
      stats_.messages_sent += sent;
      if (keepalive_due && ok) ++stats_.keepalives_sent;
    }
    if (!ok) break;
  }
  c.threads_running.fetch_sub(1);
}

ServerStats Server::stats() const {
  ServerStats s;
  {
    std::lock_guard lock(stats_mutex_);
    s = stats_;
  }
  s.clients_now = clients();
  return s;
}

std::size_t Server::clients() const {
  std::lock_guard lock(clients_mutex_);
  std::size_t n = 0;
  for (const auto& c : clients_) n += c->threads_running.load() == 2 ? 1 : 0;
  return n;
}

}  // namespace arnav::igtl
