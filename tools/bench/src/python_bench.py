"""The Python side of `troupe bench python` (run by it): times requests, says so, then reads the
scans the bench publishes and prints one JSON line of figures."""

import json
import sys
import threading
import time

import troupe

endpoint, namespace, seconds, requests = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
client = troupe.connect(endpoint, namespace=namespace)
laser = client.robot(6665).laser(0)

# Request round trips first, on a quiet network: the bench starts publishing
# when this line says they are done.
times = []
for _ in range(requests):
    t = time.perf_counter()
    laser.geometry()
    times.append(time.perf_counter() - t)
times.sort()
print("requests done", flush=True)
laser.read(timeout=10)

# A read() loop, using each scan's ranges (a numpy array when numpy is here).
reads, beams, end = 0, 0, time.perf_counter() + seconds
cpu0 = time.process_time()
while time.perf_counter() < end:
    laser.read(timeout=5)
    beams = len(laser.ranges)
    reads += 1
read_cpu = time.process_time() - cpu0

# Callbacks: every message, on the proxy's thread.
count = [0]
def on_scan(sample):
    count[0] += len(sample.data["ranges"]) > 0
sub = laser.on_data(on_scan)
time.sleep(seconds)
calls = count[0]
sub.stop()

print(json.dumps({
    "read_per_s": reads / seconds, "read_cpu": read_cpu / seconds, "beams": beams,
    "callbacks_per_s": calls / seconds, "request_p50_us": times[len(times) // 2] * 1e6,
    "request_p99_us": times[int(len(times) * 0.99)] * 1e6, "numpy": troupe._np is not None,
}))
