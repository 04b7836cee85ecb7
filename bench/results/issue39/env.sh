# Sourced from the repo root on the device by run.sh, with the call's carried folder ($1, e.g.
# .whl/gpu2/b): install its wheels into /tmp/site (once), warp.so from part-00 (carried by an
# earlier call into /tmp/parts) + the folder's part-01; the branch's tree (new.tar) to /tmp/new.
B=$(pwd)/$1
if [ ! -f /tmp/site/warp/bin/warp.so ]; then
  [ -f /tmp/parts/warp.so.zst.part-00 ] || { echo "NO PART-00: machine went cold"; return 3; }
  mkdir -p /tmp/site
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site $B/*.whl || return 1
  python3 -m zipfile -e $B/warp_lite.zip /tmp/site || return 1
  Z=$(command -v zstd); if [ -z "$Z" ]; then cp $B/zstd /tmp/zstd; chmod +x /tmp/zstd; Z=/tmp/zstd; fi
  mkdir -p /tmp/site/warp/bin  # zstd crashes on a missing output folder
  cat /tmp/parts/warp.so.zst.part-00 $B/warp.so.zst.part-01 | $Z -d --long=27 -q -o /tmp/site/warp/bin/warp.so || return 1
fi
rm -rf /tmp/new && mkdir -p /tmp/new && tar -xf $B/new.tar -C /tmp/new
export PYTHONUNBUFFERED=1
