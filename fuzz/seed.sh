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
# Maps (YAML, a NUL byte, the image), pose graphs, a fleet file, and the head of a mission log.
mkdir -p "$here/corpus/map_files" "$here/corpus/g2o_loader" "$here/corpus/fleet_config" "$here/corpus/mission_log"
shared="$here/../../shared/data"
{ cat "$shared/maps/building_31.yaml"; printf '\0'; cat "$shared/maps/building_31.png"; } > "$here/corpus/map_files/building_31"
{ cat "$shared/maps/willow-full.yaml"; printf '\0'; head -c 2048 "$shared/maps/willow-full.pgm"; } > "$here/corpus/map_files/willow-head"
for f in "$shared"/posegraph/*.g2o; do
  head -c 4096 "$f" > "$here/corpus/g2o_loader/$(basename "$f" .g2o)"
done
sed -n '/^\/\/! ```toml/,/^\/\/! ```$/p' "$here/../gcs/src/fleet_file.rs" | sed '1d;$d' | sed 's/^\/\/! \{0,1\}//' \
  > "$here/corpus/fleet_config/example.toml"
# A short mission's log, cut to its first 64 KiB (the setup and first frames): the reader must
# stop cleanly where a crash would have cut it.
log="$(mktemp -d)"
(cd "$here/.." && cargo run --quiet -p gcs -- explore --timeout 3 --out "$log" >/dev/null 2>&1) || true
if [ -f "$log/mission.mcap" ]; then
  head -c 65536 "$log/mission.mcap" > "$here/corpus/mission_log/mission-head.mcap"
fi
rm -rf "$log"
