#!/usr/bin/env bash
# Seeds the fuzz corpora from the shared real data (../shared/data) and protocol fixtures.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
data="$here/../../shared/data/mavlink"
mkdir -p "$here/corpus/mavlink_frames" "$here/corpus/tlog_reader" "$here/corpus/shield_receiver" "$here/corpus/shield_upstream" \
  "$here/corpus/camera_frames" "$here/corpus/world_text" "$here/corpus/sitl_autopilot"
cp "$data/pymavlink_capture.mav2.battery_status.tlog" "$here/corpus/tlog_reader/"
# Small slices of the real logs: whole files are too big for a fuzzer input.
for f in "$data"/*.tlog; do
  base=$(basename "$f" .tlog)
  head -c 4096 "$f" > "$here/corpus/tlog_reader/$base.head"
  tail -c 4096 "$f" > "$here/corpus/tlog_reader/$base.tail"
  head -c 4096 "$f" | tail -c 4000 > "$here/corpus/mavlink_frames/$base.raw"
done
# PROTOCOL.md's RPYT and arm examples.
printf '\x83\x74\x9b\x74\xab\x74\xb0\x00' > "$here/corpus/shield_receiver/rpyt"
printf '\xd8\x01\xdf\x7e\xd8\x01\xdf\x7e' > "$here/corpus/shield_receiver/arm"
printf '\xa5\x02\x04\x05\x01\x00\x00' > "$here/corpus/shield_upstream/ack-no-crc"
# The camera stream's fixture message, the built-in world, and real MAVLink traffic for the autopilot.
cp "$here/../link/tests/fixtures/rgbd-32x24.bin" "$here/corpus/camera_frames/"
cp "$here/../sitl/worlds/apartment.txt" "$here/corpus/world_text/"
for f in "$data"/*.tlog; do
  head -c 4096 "$f" | tail -c 4000 > "$here/corpus/sitl_autopilot/$(basename "$f" .tlog).raw"
done
