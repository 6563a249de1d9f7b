#!/usr/bin/env bash
# Configure and build the PCL reference program into benchmarks/pcl_reference/build/.
# Needs Debian's libpcl-dev (1.13.0+dfsg-3):  apt-get install -y libpcl-dev
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cmake -S "$here" -B "$here/build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$here/build" -j"$(nproc)"
echo "built: $here/build/pcl_reference"
