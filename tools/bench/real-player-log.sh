#!/usr/bin/env bash
# Writes a log with the real Player 3.1 and the real Stage 4.3, for
# `troupe bench slam --player-log LOG`: Stage's own simple.world (the 16 m
# cave), r0 alone with `localization "odom"` and `odom_error [0.03 0.03
# 0.00 0.05]`, wandering with Stage's own `wander`; Player's rangertolaser
# over the sicklaser ranger; writelog recording position2d:0 and laser:0.
# Stage's world text is read from ../shared/compat/stage, edited in a copy
# outside the repository; nothing of Player's or Stage's is committed.
#
#   tools/bench/real-player-log.sh PLAYER_GIT STAGE_GIT OUT_DIR [SECONDS] [WORLD]
#
# PLAYER_GIT and STAGE_GIT are git directories of github:playerproject/player
# and github:rtv/Stage (as the project's fetch brings them); both are built
# once (about 17 minutes on two cores) under OUT_DIR/build and kept there.
# SECONDS is simulated time (905 by default). The log is OUT_DIR/cave-r0.log.
# WORLD, a world of ours in Stage's language (worlds/slam.world: its r0
# drives with Stage's own `wander` and odometry 3% long), is run instead,
# as written but ten times real time, beside the .inc files of its
# directory; the log is then OUT_DIR/NAME-r0.log (NAME: WORLD's stem).
set -euo pipefail

if [ $# -lt 3 ]; then
  sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
player_git=$(realpath "$1")
stage_git=$(realpath "$2")
out=$(realpath -m "$3")
seconds=${4:-905}
world=${5:+$(realpath "$5")}
here=$(cd "$(dirname "$0")" && pwd)
compat=$(realpath "$here/../../../shared/compat/stage")
build=$out/build
prefix=$build/prefix
mkdir -p "$build"

need=(cmake g++ pkg-config libfltk1.3-dev fluid libgl-dev libglu1-mesa-dev libltdl-dev
  libpng-dev libjpeg-dev zlib1g-dev libgtk2.0-dev libboost-thread-dev
  libboost-system-dev libxmu-dev)
missing=()
for p in "${need[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing ${missing[*]}" >&2
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# Player: the flags REFERENCE.md gives (-O2 -g without NDEBUG, gnu++14, no
# Boost.Signals, no Python 2 bindings).
if [ ! -x "$prefix/bin/player" ]; then
  rm -rf "$build/player" && mkdir -p "$build/player/src" "$build/player/build"
  git --git-dir="$player_git" archive HEAD | tar -x -C "$build/player/src"
  (cd "$build/player/build" && cmake ../src -DCMAKE_INSTALL_PREFIX="$prefix" \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g" \
    -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g" -DCMAKE_CXX_STANDARD=14 \
    -DCMAKE_CXX_FLAGS="-std=gnu++14" -DUSE_BOOST_SIGNALS=OFF -DBoost_NO_BOOST_CMAKE=ON \
    -DBUILD_PYTHONC_BINDINGS=OFF -DBUILD_PYTHONCPP_BINDINGS=OFF -DBUILD_RUBYCPP_BINDINGS=OFF \
    >"$build/player.log" 2>&1 && make -j2 install >>"$build/player.log" 2>&1) \
    || { echo "Player's build failed: $build/player.log" >&2; exit 1; }
fi
export PATH=$prefix/bin:$PATH
export LD_LIBRARY_PATH=$prefix/lib:$prefix/lib64:${LD_LIBRARY_PATH:-}
export PKG_CONFIG_PATH=$prefix/lib/pkgconfig:$prefix/lib64/pkgconfig:${PKG_CONFIG_PATH:-}
if [ ! -e "$prefix/lib/stage/stageplugin.so" ] && [ ! -e "$prefix/lib64/stage/stageplugin.so" ]; then
  rm -rf "$build/stage" && mkdir -p "$build/stage/src" "$build/stage/build"
  git --git-dir="$stage_git" archive HEAD | tar -x -C "$build/stage/src"
  (cd "$build/stage/build" && cmake ../src -DCMAKE_INSTALL_PREFIX="$prefix" \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo >"$build/stage.log" 2>&1 \
    && make -j2 install >>"$build/stage.log" 2>&1) \
    || { echo "Stage's build failed: $build/stage.log" >&2; exit 1; }
fi
plugin_dir=$(dirname "$(find "$prefix" -name stageplugin.so | head -1)")
export PLAYERPATH=$plugin_dir:$prefix/lib:$prefix/lib64
export STAGEPATH=$plugin_dir

work=$(mktemp -d)
trap 'kill "${player_pid:-0}" 2>/dev/null || true; rm -rf "$work"' EXIT
if [ -n "$world" ]; then
  # A world of ours, as written, at ten times real time.
  name=$(basename "$world" .world)
  cp "$(dirname "$world")"/*.inc "$work/"
  sed 's/^speedup .*/speedup 10/' "$world" >"$work/$name.world"
else
  # Stage's simple.world as the cave, r0 alone, its odometry off as the
  # issue that asked for this log says.
  name=cave
  cp -r "$compat"/*.inc "$compat/bitmaps" "$work/"
  python3 - "$compat/simple.world" "$work/cave.world" <<'EOF'
import re, sys
text = open(sys.argv[1]).read()
# r1 goes: the second pioneer2dx block.
blocks = [m.start() for m in re.finditer(r"^pioneer2dx\s*\(", text, re.M)]
if len(blocks) > 1:
    start = blocks[1]
    depth, i = 0, text.index("(", start)
    while True:
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        i += 1
        if depth == 0:
            break
    text = text[:start] + text[i:]
text = text.replace('localization "gps"', 'localization "odom"\n  odom_error [0.03 0.03 0.00 0.05]', 1)
open(sys.argv[2], "w").write(text)
EOF
fi
cat >"$work/log.cfg" <<EOF
driver ( name "stage" provides ["simulation:0"] plugin "stageplugin" worldfile "$name.world" usegui 0 )
driver ( name "stage" provides ["position2d:0" "ranger:0" "ranger:1"] model "r0" )
driver ( name "rangertolaser" provides ["laser:0"] requires ["ranger:1"] )
driver ( name "writelog" provides ["log:0"] requires ["position2d:0" "laser:0"] filename "$name-r0.log" alwayson 1 )
EOF
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
(cd "$work" && exec player -p "$port" log.cfg >"$work/player.out" 2>&1) &
player_pid=$!
# Until the log's last stamp passes SECONDS of simulated time.
last=0
while kill -0 "$player_pid" 2>/dev/null; do
  sleep 2
  if [ -s "$work/$name-r0.log" ]; then
    last=$(tail -c 2000 "$work/$name-r0.log" | awk 'NF > 7 && $1 !~ /^#/ { t = $1 } END { print t + 0 }')
    first=$(awk 'NF > 7 && $1 !~ /^#/ { print $1; exit }' "$work/$name-r0.log")
    if awk -v a="$last" -v b="$first" -v s="$seconds" 'BEGIN { exit !(a - b >= s) }'; then
      break
    fi
  fi
done
kill "$player_pid" 2>/dev/null || true
wait "$player_pid" 2>/dev/null || true
if [ ! -s "$work/$name-r0.log" ]; then
  echo "Player wrote no log; it said:" >&2
  cat "$work/player.out" >&2
  exit 1
fi
mkdir -p "$out"
cp "$work/$name-r0.log" "$out/$name-r0.log"
echo "$out/$name-r0.log: $(wc -l <"$out/$name-r0.log") lines, $(awk 'NF > 7 && $1 !~ /^#/ { if (!f) f = $1; t = $1 } END { printf "%.0f", t - f }' "$out/$name-r0.log") simulated s"
