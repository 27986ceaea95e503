#!/usr/bin/env python3
"""The `security:` line of scripts/demo's AR session (ar_session.sh; docs/security.md).

    security_report.py HOST_JSON APPLIANCE_LOG [ATTACK_JSON]

Every figure of the line comes from arnav-host's own counters (--summary-json, "security"):
the messages it rejected by kind are the injections it saw; "accepted" counts injected
messages the host accepted, from its audit of accepted senders: a message from a sender
arnav-appliance did not announce ("security: publishing as sender ..." in its log), or a
(sender, counter) accepted twice. The attacker's own report, when given, is printed beside
it for comparison, never used for the line. Exit 0; 3 when an injected message was
accepted; 2 when the bus was not sealed or a file is missing or unreadable.
"""
import json
import re
import sys


def main(argv):
    if len(argv) not in (3, 4):
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        host = json.load(open(argv[1]))
        appliance_log = open(argv[2]).read()
        attack = json.load(open(argv[3])) if len(argv) == 4 else None
    except (OSError, ValueError) as e:
        print("security: no report (%s)" % e)
        return 2
    sec = host.get("security", {})
    if sec.get("mode") != "sealed":
        print("security: the bus was not sealed (security: %s in the session file): nothing to report" % sec.get("mode", "?"))
        return 2
    ours = set(re.findall(r"security: publishing as sender ([0-9a-f]{16})", appliance_log))
    senders = sec.get("senders", [])
    foreign = [s for s in senders if s["sender"] not in ours]
    twice = sum(s["accepted_twice"] for s in senders)
    accepted_injected = sum(s["accepted"] for s in foreign) + twice
    kinds = ["forged", "replayed", "tampered", "unsealed", "stale", "malformed"]
    n = {k: sec[k] for k in kinds}
    injected = sum(n.values())
    shown = "/".join("%s %d" % (k, n[k]) for k in kinds if k in ("forged", "replayed", "tampered") or n[k] > 0)
    print("security: %d injected (%s), %d accepted" % (injected, shown, accepted_injected))
    print("  arnav-host's counters (key id %s): %d genuine messages accepted from %d sender(s), %s; %d accepted twice"
          % (sec.get("key_id", "?"), sec["accepted"], len(senders),
             "all announced by arnav-appliance" if not foreign else "%d NOT announced by arnav-appliance" % len(foreign), twice))
    if any(s.get("audit_truncated") for s in senders):
        print("  (a sender's counter passed the audit's range: its repeats beyond it were not checked)")
    if attack is not None:
        sent = attack.get("total", 0)
        print("  the attacker's own count, for comparison: %d sent (unsealed %d, forged %d, replayed %d, tampered %d, stale %d); "
              "the host counted %d of them%s"
              % (sent, attack.get("unsealed", 0), attack.get("forged", 0), attack.get("replayed", 0), attack.get("tampered", 0),
                 attack.get("stale", 0), injected,
                 " (the rest lost on the loaded bus: UDP, counted by nobody, accepted by nobody)" if injected < sent else ""))
    nav = host.get("navigation", {})
    flags = nav.get("flags", {})
    banner_frames = max(flags.get("security_rejected", {}).get("frames", 0), flags.get("security_unsealed", {}).get("frames", 0))
    alerts = nav.get("security_banner", {}).get("alerts", 0)
    if nav:
        print("  overlay: SECURITY banner on %d of %d frames displayed (%d alert(s))"
              % (banner_frames, nav.get("frames_displayed", 0), alerts))
    if not ours:
        print("security: arnav-appliance announced no sender (no 'publishing as sender' line in %s): the accepted senders cannot be checked" % argv[2])
        return 2
    return 3 if accepted_injected > 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
