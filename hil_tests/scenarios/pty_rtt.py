#!/usr/bin/env python3
# Round-trip time of a bare pseudo-terminal between two SCHED_FIFO processes (root), the
# floor under every HIL bench figure: pty data is moved by kernel worker threads that run
# with normal scheduling, so on a loaded machine a round trip can take milliseconds even
# when both ends are real-time. Usage: hil_tests/scenarios/pty_rtt.py [ROUND_TRIPS=4000]
# (one 1-byte poll and a 64-byte answer every ~2.2 ms, like BX at 400 Hz).
import os, pty, time, sys, tty, select
master, slave = pty.openpty()
tty.setraw(slave); tty.setraw(master)
pid = os.fork()
if pid == 0:
    os.close(slave)  # so the echo side sees EIO and exits when the prober goes away
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
    while True:
        try:
            b = os.read(master, 64)
        except OSError:
            os._exit(0)
        if b == b'q' or not b: os._exit(0)
        os.write(master, b'r'*64)
os.close(master)
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
n = int(sys.argv[1]) if len(sys.argv) > 1 else 4000; rtts = []
for i in range(n):
    t0 = time.perf_counter_ns()
    os.write(slave, b'p')
    got = 0
    while got < 64: got += len(os.read(slave, 64))
    rtts.append((time.perf_counter_ns() - t0) / 1000)
    time.sleep(0.0022)
os.write(slave, b'q'); os.waitpid(pid, 0)
rtts.sort()
q = lambda p: rtts[min(len(rtts)-1, int(p*len(rtts)))]
print("n", n, "p50 %.0f p99 %.0f p999 %.0f max %.0f us; >1ms %d >2.5ms %d" % (q(.5), q(.99), q(.999), rtts[-1], sum(r>1000 for r in rtts), sum(r>2500 for r in rtts)), "load", open('/proc/loadavg').read().split()[:3])
