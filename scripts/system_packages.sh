#!/bin/sh
# System packages pip cannot bring: FFmpeg's shared libraries for torchcodec (LeRobot video
# decoding in the LeRobot export test) and Chromium (the HTML report's headless-browser test).
# Installs only what is missing, with apt-get (as root, or through sudo); elsewhere it says what
# to install and goes on (those tests then skip, saying why).
set -u
need=""
ldconfig -p 2>/dev/null | grep -q "libavcodec.so.59" || need="libavcodec59 libavformat59 libavutil57 libswscale6 libswresample4 libavdevice59 libavfilter8"
command -v chromium >/dev/null 2>&1 || need="$need chromium"
[ -z "$need" ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "system_packages.sh: install $need (FFmpeg 5 libraries for torchcodec, Chromium); going on without them" >&2
    exit 0
fi
SUDO=""
[ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo -n"
$SUDO apt-get install -y -qq $need >/dev/null 2>&1 || { $SUDO apt-get update -qq >/dev/null 2>&1 && $SUDO apt-get install -y -qq $need >/dev/null 2>&1; } \
    || echo "system_packages.sh: could not install $need (no root?); the tests that need them will skip" >&2
exit 0
