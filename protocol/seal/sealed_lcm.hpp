#pragma once
// SealedLcm: an lcm::LCM with the sealed bus built in (docs/protocol.md, "Sealed bus").
// It offers the part of lcm::LCM the programs use (publish, subscribe with a handler
// method, handle, handleTimeout, getFileno, good), so a caller changes only the type:
//   seal::SealedLcm bus(url, security);  bus.publish(channel, &msg);
//   bus.subscribe(regex, &Handler::pose, &handler);  bus.handleTimeout(20);
// Sealed: every publish seals the encoded message (one sender id per instance); every
// received message is opened once, whatever number of subscriptions match it, and only an
// accepted one is decoded and handed on. Off: plain LCM, announced by describe().
#include <lcm/lcm-cpp.hpp>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "protocol/seal/channel_guard.hpp"
#include "protocol/seal/security_config.hpp"

namespace arnav::seal {

// What one sender had accepted (sealed buses): an audit kept apart from the opener's replay
// window, so a report can show every accepted message came from a known publisher, once.
struct SenderTally {
  std::string sender;                 // sender_hex
  std::uint64_t accepted = 0;         // messages accepted from it
  std::uint64_t highest = 0;          // its highest counter accepted
  std::uint64_t accepted_twice = 0;   // a (sender, counter) accepted again: must stay 0
  bool audit_truncated = false;       // counters beyond kAuditCounters not checked for repeats
};

struct BusCounters {
  OpenCounters open;            // per verdict (sealed); on an off bus only `accepted`
  std::vector<SenderTally> senders;  // sealed: every sender accepted from (at most kAuditSenders)
  std::uint64_t undecodable = 0;  // accepted but not the subscribed type (another schema)
  std::uint64_t sealed_on_off_bus = 0;  // envelopes met with security off: cannot be read
};

class SealedLcm {
 public:
  static constexpr std::size_t kAuditSenders = 256;
  static constexpr std::uint64_t kAuditCounters = std::uint64_t{1} << 26;  // 8 MiB of bits per sender at most
  // Called with the sender id (sender_hex) of every sealed instance made from now on, on the
  // constructing thread: a program that publishes says which senders are its own (the
  // appliance's log; scripts/demo compares them with the host's accepted senders). Set once,
  // before the instances are made (not synchronised).
  static void announce_senders(std::function<void(const std::string& sender)> announcer);

  SealedLcm(const std::string& url, BusSecurity security);
  SealedLcm(const SealedLcm&) = delete;
  SealedLcm& operator=(const SealedLcm&) = delete;

  bool good() { return lcm_.good(); }
  bool sealed() const { return security_.sealed(); }
  std::string describe() const { return security_.describe(); }

  template <class Msg>
  int publish(const std::string& channel, const Msg* msg) {
    std::lock_guard lock(publish_mutex_);
    const int n = msg->getEncodedSize();
    encoded_.resize(static_cast<std::size_t>(n));
    if (msg->encode(encoded_.data(), 0, n) != n) return -1;
    return publish_locked(channel, encoded_.data(), encoded_.size());
  }
  int publish_bytes(const std::string& channel, const void* data, std::size_t size);

  // A handler method taking the decoded message, as lcm::LCM::subscribe.
  template <class Msg, class Handler>
  void subscribe(const std::string& channel_regex, void (Handler::*method)(const lcm::ReceiveBuffer*, const std::string&, const Msg*), Handler* handler) {
    add_subscription(channel_regex, [this, method, handler](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      Msg msg;
      if (msg.decode(rbuf->data, 0, rbuf->data_size) < 0) {
        ++undecodable_;
        return;
      }
      (handler->*method)(rbuf, channel, &msg);
    });
  }
  // A handler method taking the (opened) bytes, as lcm::LCM::subscribe's raw form.
  template <class Handler>
  void subscribe(const std::string& channel_regex, void (Handler::*method)(const lcm::ReceiveBuffer*, const std::string&), Handler* handler) {
    add_subscription(channel_regex, [method, handler](const lcm::ReceiveBuffer* rbuf, const std::string& channel) { (handler->*method)(rbuf, channel); });
  }

  int handle();
  int handleTimeout(int timeout_ms);
  int getFileno() { return lcm_.getFileno(); }
  // The plain bus underneath (bypasses sealing): for the bench's attacker and for tests.
  lcm::LCM& raw() { return lcm_; }
  // Receive-side counters (read on the thread that calls handle()).
  BusCounters counters() const;
  // Called once for every received message the opener drops (not for an accepted one), on
  // the thread that calls handle(), with its verdict and channel: the host's security
  // banner (host/app/security_alarm.hpp). Sealed buses only; one observer (a second replaces it).
  using DropObserver = std::function<void(Verdict, const std::string& channel)>;
  void on_drop(DropObserver observer) { drop_observer_ = std::move(observer); }
  // "sealed: accepted N; dropped M (forged a, tampered b, replayed c, stale d, unsealed e,
  // malformed f)" or the OFF announcement; one line, for status tables.
  std::string status_line() const;

 private:
  using RawHandler = std::function<void(const lcm::ReceiveBuffer*, const std::string&)>;
  struct Subscription {
    SealedLcm* bus;
    RawHandler handler;
    void on_raw(const lcm::ReceiveBuffer* rbuf, const std::string& channel) { bus->deliver(*this, rbuf, channel); }
  };
  int publish_locked(const std::string& channel, const void* data, std::size_t size);
  void add_subscription(const std::string& channel_regex, RawHandler handler);
  void deliver(Subscription& s, const lcm::ReceiveBuffer* rbuf, const std::string& channel);

  lcm::LCM lcm_;
  BusSecurity security_;
  std::mutex publish_mutex_;
  std::vector<std::uint8_t> encoded_, sealed_;
  std::unique_ptr<Sealer> sealer_;
  std::unique_ptr<Opener> opener_;
  std::vector<std::unique_ptr<Subscription>> subscriptions_;
  // One LCM handle() dispatches one message to every matching subscription: it is opened
  // for the first and the verdict and plaintext reused for the others (a second open would
  // read as a replay).
  std::uint64_t dispatch_ = 0, opened_dispatch_ = 0;
  Verdict last_verdict_ = Verdict::Unsealed;
  std::vector<std::uint8_t> plain_;
  std::uint64_t accepted_off_ = 0, undecodable_ = 0, sealed_on_off_bus_ = 0;
  DropObserver drop_observer_;
  struct Audit {
    SenderTally tally;
    std::vector<bool> seen;  // bit c: counter c accepted
  };
  void audit(const EnvelopeHeader& h);
  std::map<SenderId, Audit> audit_;
  std::uint64_t audit_overflow_ = 0;  // accepted from senders beyond kAuditSenders
};

}  // namespace arnav::seal
