# Sourced by the device runs' scripts (gpu4/run.sh, gpu5/run.sh, device_run.sh): installs the
# carried cp312 wheels into $S on a GPU machine that has no registry, once per warm machine.
# Needs B (the carried bundle: wheels, warp_lite.zip, warp.so.zst.part-01, zstd, and for
# WARPCACHE=1 warpcache.tar.zst), S (the target folder) and L (the log). warp.so is split in two
# because part-00 alone fills a call's carry: an earlier call on the same machine leaves it in
# /tmp/parts.
Z=$(command -v zstd); if [ -z "$Z" ]; then cp $B/zstd /tmp/zstd; chmod +x /tmp/zstd; Z=/tmp/zstd; fi
if [ ! -f $S/warp/bin/warp.so ]; then
  [ -f /tmp/parts/warp.so.zst.part-00 ] || { echo "NO PART-00: machine went cold" | tee -a $L; exit 3; }
  mkdir -p $S/warp/bin
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target $S $B/*.whl || exit 1
  python3 -m zipfile -e $B/warp_lite.zip $S || exit 1
  cat /tmp/parts/warp.so.zst.part-00 $B/warp.so.zst.part-01 | $Z -d --long=27 -q -o $S/warp/bin/warp.so || exit 1
  if [ "${WARPCACHE:-0}" = 1 ]; then
    rm -rf ~/.cache/warp && mkdir -p ~/.cache && $Z -d -q -c $B/warpcache.tar.zst | tar -xf - -C ~/.cache || exit 1
  fi
fi
