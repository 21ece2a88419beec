"""A raw Zenoh peer, as anyone on a network can run one (eclipse-zenoh, the Zenoh that dora 1.1 speaks),
run as a script on a machine of the namespace rig (tests/test_two_machines.py). argv: endpoints (comma
separated), a mode, a file:

- `capture FILE SECONDS`: keeps every joint_cmd sample it hears (key, payload) for SECONDS, to FILE.
- `replay FILE HEARD SECONDS`: publishes the samples FILE holds, each five times, as they were heard,
  while it listens to every key for SECONDS; writes what it heard of the others, {key: samples}, as
  JSON to HEARD.

It prints `open failed: ...` where no session opens; a session whose endpoints all fail still opens
(Zenoh keeps trying) and hears nothing.
"""

import json
import pickle
import sys
import time

import zenoh

endpoints, mode, path = sys.argv[1].split(","), sys.argv[2], sys.argv[3]
config = zenoh.Config()
config.insert_json5("mode", '"peer"')
config.insert_json5("connect/endpoints", json.dumps(endpoints))
# A peer listens on every address by default, and dora's daemons, told of it, dial it there: across the lab
# network, in clear, past the tunnel. Loopback only, as dora's own nodes listen.
config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
try:
    session = zenoh.open(config)
except Exception as error:  # noqa: BLE001 - any failure to open is the answer
    print(f"open failed: {error}", flush=True)
    sys.exit(0)
print("open", flush=True)
if mode == "capture":
    samples: list[tuple[str, bytes]] = []
    subscriber = session.declare_subscriber("**/joint_cmd", lambda sample: samples.append(
        (str(sample.key_expr), sample.payload.to_bytes())))
    time.sleep(float(sys.argv[4]))
    with open(path, "wb") as file:
        pickle.dump(samples, file)
else:
    heard: dict[str, int] = {}
    subscriber = session.declare_subscriber("**", lambda sample: heard.__setitem__(
        str(sample.key_expr), heard.get(str(sample.key_expr), 0) + 1))
    with open(path, "rb") as file:
        samples = pickle.load(file)
    until = time.monotonic() + float(sys.argv[5])
    time.sleep(1)  # the links and the subscribers' declarations first
    for key, payload in samples:
        for _ in range(5):
            session.put(key, payload, allowed_destination=zenoh.Locality.REMOTE)  # not to its own subscriber
            time.sleep(0.1)
    time.sleep(max(1.0, until - time.monotonic()))
    with open(sys.argv[4], "w") as file:
        json.dump(heard, file)
print(f"{mode} done", flush=True)
session.close()
