#!/usr/bin/env bash
# Make sure the Qt binding in the venv can start offscreen; if it cannot, install the Debian runtime
# libraries it needs and check again.
#
# Usage: .ci/ensure_qt_libs.sh [PATH_TO_VENV_PYTHON]     (default .venv/bin/python)
#
# Silent and quick when Qt already works (the usual case); idempotent. The PySide6 wheels bundle Qt
# itself but link these system libraries. The list was found by experiment on a minimal Debian 12
# (debootstrap --variant=minbase plus python3, make, git): install the wheels, run the check below,
# and add packages until it passes (ldd on libqoffscreen.so, libQt6Gui, libQt6Widgets shows which
# sonames are "not found").
set -euo pipefail

PY="${1:-.venv/bin/python}"

# Debian package       soname(s) that libQt6Core/Gui/Widgets and libqoffscreen.so link
QT_DEB_PACKAGES=(
    libglib2.0-0        # libglib-2.0.so.0, libgthread-2.0.so.0 (QtCore's event loop)
    libgl1              # libGL.so.1 (pulls libglx0 and libx11-6)
    libegl1             # libEGL.so.1
    libx11-6            # libX11.so.6 (also a dependency of libgl1; named for clarity)
    libxkbcommon0       # libxkbcommon.so.0
    libfontconfig1      # libfontconfig.so.1 (pulls libfreetype6 and a default font)
    libfreetype6        # libfreetype.so.6 (also a dependency of libfontconfig1)
    libdbus-1-3         # libdbus-1.so.3
)

# What the tests and the demo need: a QApplication on the offscreen platform, and pyqtgraph.
CHECK='
import sys
from PySide6.QtWidgets import QApplication
app = QApplication(sys.argv[:1])
import pyqtgraph
assert QApplication.platformName() == "offscreen", QApplication.platformName()
'

# Run the check; its output (a traceback, Qt's plugin errors) is kept in $CHECK_OUTPUT.
CHECK_OUTPUT=""
qt_works() {
    CHECK_OUTPUT="$(QT_QPA_PLATFORM=offscreen timeout 120 "$PY" -c "$CHECK" 2>&1)"
}

# Print the system libraries that the Qt libraries and the offscreen plugin cannot find.
missing_sonames() {
    local qt_dir
    qt_dir="$("$PY" -c 'import os, PySide6; print(os.path.join(os.path.dirname(PySide6.__file__), "Qt"))' \
        2>/dev/null)" || return 0
    ldd "$qt_dir"/plugins/platforms/libqoffscreen.so "$qt_dir"/lib/libQt6Gui.so.* \
        "$qt_dir"/lib/libQt6Widgets.so.* "$qt_dir"/lib/libQt6Core.so.* 2>/dev/null \
        | awk '/not found/ {print $1}' | sort -u
}

if [[ ! -x "$PY" ]]; then
    echo "ensure_qt_libs: $PY not found; make the venv first" >&2
    exit 1
fi

if qt_works; then
    exit 0
fi

MISSING="$(missing_sonames | tr '\n' ' ')"
if [[ -z "$MISSING" && "$CHECK_OUTPUT" != *".so"* ]]; then
    # Not a missing system library (e.g. PySide6 itself is not installed): apt-get cannot help.
    echo "ensure_qt_libs: Qt cannot start offscreen, and no system library is missing:" >&2
    echo "$CHECK_OUTPUT" | tail -n 25 >&2
    exit 1
fi
echo "ensure_qt_libs: Qt cannot start offscreen; missing libraries: ${MISSING:-none found by ldd}"
if [[ -z "$MISSING" ]]; then
    echo "$CHECK_OUTPUT" | tail -n 10
fi

if ! command -v apt-get >/dev/null 2>&1; then
    echo "ensure_qt_libs: no apt-get here; install the equivalents of these Debian packages:" \
        "${QT_DEB_PACKAGES[*]}" >&2
    exit 1
fi

SUDO=()
if [[ "$(id -u)" -ne 0 ]]; then
    if command -v sudo >/dev/null 2>&1; then
        SUDO=(sudo)
    else
        echo "ensure_qt_libs: not root and no sudo; as root run:" \
            "apt-get install -y --no-install-recommends ${QT_DEB_PACKAGES[*]}" >&2
        exit 1
    fi
fi

echo "ensure_qt_libs: installing ${QT_DEB_PACKAGES[*]}"
"${SUDO[@]}" apt-get update -qq
"${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive \
    apt-get install -y -qq --no-install-recommends "${QT_DEB_PACKAGES[@]}" >/dev/null

if ! qt_works; then
    echo "ensure_qt_libs: Qt still cannot start offscreen after the install. Details:" >&2
    echo "  missing libraries: $(missing_sonames | tr '\n' ' ')" >&2
    QT_QPA_PLATFORM=offscreen QT_DEBUG_PLUGINS=1 timeout 120 "$PY" -c "$CHECK" 2>&1 \
        | tail -n 25 >&2 || true
    exit 1
fi
echo "ensure_qt_libs: Qt starts offscreen now"
