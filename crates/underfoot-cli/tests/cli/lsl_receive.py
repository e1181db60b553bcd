"""An independent LSL client for the tests: resolves underfoot's strike and marker
streams with pylsl, then prints every sample with its timestamp as JSON.

    python3 lsl_receive.py SECONDS

Prints READY once both streams are open, then, after SECONDS, one JSON object:
{"underfoot strikes": [[sample, timestamp], ...], "underfoot markers": [...]}.
"""

import json
import sys
import time

import pylsl

NAMES = ["underfoot strikes", "underfoot markers"]

seconds = float(sys.argv[1])
inlets = {}
deadline = time.time() + 30
seen = set()
while len(inlets) < len(NAMES) and time.time() < deadline:
    for info in pylsl.resolve_streams(wait_time=1.0):
        seen.add(info.name())
        if info.name() in NAMES and info.name() not in inlets:
            inlet = pylsl.StreamInlet(info, max_buflen=60)
            inlet.open_stream(timeout=10)
            inlets[info.name()] = inlet
if len(inlets) < len(NAMES):
    sys.exit(f"found only {sorted(inlets)} of {NAMES} (streams seen: {sorted(seen)})")
print("READY", flush=True)
received = {name: [] for name in NAMES}
end = time.time() + seconds
while time.time() < end:
    for name, inlet in inlets.items():
        sample, timestamp = inlet.pull_sample(timeout=0.02)
        if sample is not None:
            received[name].append([json.loads(sample[0]), timestamp])
print(json.dumps(received), flush=True)
