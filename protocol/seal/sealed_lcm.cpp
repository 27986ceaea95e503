#include "protocol/seal/sealed_lcm.hpp"

#include <sys/time.h>

#include <algorithm>
#include <span>

namespace arnav::seal {

namespace {
std::int64_t wall_now_us() {
  timeval tv{};
  ::gettimeofday(&tv, nullptr);
  return static_cast<std::int64_t>(tv.tv_sec) * 1000000 + tv.tv_usec;
}
std::function<void(const std::string&)>& announcer() {
  static std::function<void(const std::string&)> a;
  return a;
}
}  // namespace

void SealedLcm::announce_senders(std::function<void(const std::string& sender)> a) { announcer() = std::move(a); }

SealedLcm::SealedLcm(const std::string& url, BusSecurity security) : lcm_(url), security_(std::move(security)) {
  if (security_.key) {
    sealer_ = std::make_unique<Sealer>(security_.key);
    opener_ = std::make_unique<Opener>(security_.key, security_.options);
    if (announcer()) announcer()(sender_hex(sealer_->sender()));
  }
}

void SealedLcm::audit(const EnvelopeHeader& h) {
  auto it = audit_.find(h.sender);
  if (it == audit_.end()) {
    if (audit_.size() >= kAuditSenders) {
      ++audit_overflow_;
      return;
    }
    it = audit_.emplace(h.sender, Audit{}).first;
    it->second.tally.sender = sender_hex(h.sender);
  }
  SenderTally& t = it->second.tally;
  ++t.accepted;
  t.highest = std::max(t.highest, h.counter);
  if (h.counter >= kAuditCounters) {
    t.audit_truncated = true;
    return;
  }
  std::vector<bool>& seen = it->second.seen;
  if (seen.size() <= h.counter) seen.resize(std::max<std::size_t>(h.counter + 1, seen.size() * 2));
  if (seen[h.counter]) ++t.accepted_twice;
  seen[h.counter] = true;
}

int SealedLcm::publish_bytes(const std::string& channel, const void* data, std::size_t size) {
  std::lock_guard lock(publish_mutex_);
  return publish_locked(channel, data, size);
}

int SealedLcm::publish_locked(const std::string& channel, const void* data, std::size_t size) {
  if (!sealer_) return lcm_.publish(channel, data, static_cast<unsigned int>(size));
  sealer_->seal(channel, std::span<const std::uint8_t>(static_cast<const std::uint8_t*>(data), size), wall_now_us(), sealed_);
  return lcm_.publish(channel, sealed_.data(), static_cast<unsigned int>(sealed_.size()));
}

void SealedLcm::add_subscription(const std::string& channel_regex, RawHandler handler) {
  subscriptions_.push_back(std::make_unique<Subscription>(Subscription{this, std::move(handler)}));
  lcm_.subscribe(channel_regex, &Subscription::on_raw, subscriptions_.back().get());
}

int SealedLcm::handle() {
  ++dispatch_;
  return lcm_.handle();
}

int SealedLcm::handleTimeout(int timeout_ms) {
  ++dispatch_;
  return lcm_.handleTimeout(timeout_ms);
}

void SealedLcm::deliver(Subscription& s, const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  const std::span<const std::uint8_t> bytes(static_cast<const std::uint8_t*>(rbuf->data), rbuf->data_size);
  if (!opener_) {
    if (opened_dispatch_ != dispatch_) {
      opened_dispatch_ = dispatch_;
      if (looks_sealed(bytes)) ++sealed_on_off_bus_;
      else ++accepted_off_;
    }
    if (!looks_sealed(bytes)) s.handler(rbuf, channel);
    return;
  }
  if (opened_dispatch_ != dispatch_) {
    opened_dispatch_ = dispatch_;
    last_verdict_ = opener_->open(channel, bytes, rbuf->recv_utime, plain_);
    if (last_verdict_ == Verdict::Accepted) audit(opener_->last_header());
    else if (drop_observer_) drop_observer_(last_verdict_, channel);
  }
  if (last_verdict_ != Verdict::Accepted) return;
  lcm::ReceiveBuffer opened{plain_.data(), static_cast<std::uint32_t>(plain_.size()), rbuf->recv_utime};
  s.handler(&opened, channel);
}

BusCounters SealedLcm::counters() const {
  BusCounters c;
  if (opener_) c.open = opener_->counters();
  else c.open.accepted = accepted_off_;
  c.undecodable = undecodable_;
  c.sealed_on_off_bus = sealed_on_off_bus_;
  for (const auto& [id, a] : audit_) c.senders.push_back(a.tally);
  return c;
}

std::string SealedLcm::status_line() const {
  if (!opener_) {
    std::string s = security_.describe();
    if (sealed_on_off_bus_ > 0) s += "; " + std::to_string(sealed_on_off_bus_) + " sealed messages ignored (no key)";
    return s;
  }
  const OpenCounters c = opener_->counters();
  std::string s = "security: sealed, key id " + security_.key->key_id_hex() + ": " + format_counters(c);
  if (c.dropped() > 0) s = "SECURITY ALERT: " + std::to_string(c.dropped()) + " messages rejected; " + s;
  return s;
}

}  // namespace arnav::seal
