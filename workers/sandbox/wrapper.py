"""The shell wrapper every docker sandbox command runs in, and the parser of what it prints.

Why a wrapper inside the container (rather than reading the command's raw output on the host):

* the output cap and the true output size are computed *inside* (``tee`` into ``wc -c`` and
  ``head -c``), so a command that prints gigabytes (``yes``) never streams them to the host;
* ``timeout -s KILL`` kills the command's process group when its time is up, even when the
  host-side guard (:mod:`workers.sandbox.docker_sandbox`) is not needed;
* nothing outlives its command: when the command returns, every process in the container except
  the init, its keeper and the wrapper's own readers is stopped then killed (background jobs,
  ``setsid`` daemons, a fork bomb's children). Otherwise a stray holding the output pipe open
  would hang the command, and a fork bomb would keep its pids;
* a disk watchdog runs ``du`` on the repository folder every second while the command runs and
  kills it when the folder is over the disk limit (overlay2 has no per-container quota here);
  ``ulimit -f`` caps any single file at the same size.

The wrapper needs only bash and coreutils (``timeout``, ``tee``, ``head``, ``wc``, ``du``), so it
also works in images other than ours. It prints the cut output, then one trailer line
``\\n<nonce> <rc> <output bytes> <repo bytes> <disk kill>``; the nonce is random per command, so no
command output can forge it.
"""

from __future__ import annotations

from dataclasses import dataclass

WRAPPER = r"""
nonce=$1 tmo=$2 cap=$3 disk=$4 wd=$5 keep=$6 cmd=$7
exec 2>/dev/null
d=/tmp/.recap-$nonce
mkdir -p "$d" && mkfifo "$d/o" "$d/c" "$d/h" || { echo "sandbox wrapper: cannot create $d"; exit 97; }
wc -c < "$d/c" > "$d/size" & pw=$!
head -c "$cap" < "$d/h" 2>/dev/null & ph=$!
tee -p "$d/c" "$d/h" < "$d/o" > /dev/null & pt=$!
( ulimit -f $(( disk / 1024 + 1 )); cd "$wd" && exec timeout -s KILL "$tmo" bash -c "$cmd" ) > "$d/o" 2>&1 < /dev/null & pc=$!
( while sleep 1; do
    s=$(du -sb "$wd" 2>/dev/null) ; s=${s%%[[:space:]]*}
    if [ "${s:-0}" -gt "$disk" ]; then echo "$s" > "$d/disk"; kill -KILL -- "-$pc" "$pc"; break; fi
  done ) & pd=$!
wait "$pc"; rc=$?
kill -KILL "$pd"
keepset=" 1 $keep $$ $pw $ph $pt "
sweep() {  # signal every process but ours; status 0 when it signalled one
  local sig=$1 p st found=1
  for p in /proc/[0-9]*; do
    p=${p#/proc/}
    case "$keepset" in *" $p "*) continue ;; esac
    read -r st < "/proc/$p/stat" || continue
    st=${st##*) }
    case "${st:0:1}" in Z) continue ;; T) [ "$sig" = STOP ] && continue ;; esac
    kill "-$sig" "$p" && found=0
  done
  return $found
}
for ((i = 0; i < 100; i++)); do sweep STOP || break; done
for ((i = 0; i < 100; i++)); do sweep KILL || break; done
wait "$pt" "$ph" "$pw"
size=$(cat "$d/size" 2>/dev/null)
killed=$(cat "$d/disk" 2>/dev/null)
used=$(du -sb "$wd" 2>/dev/null); used=${used%%[[:space:]]*}
rm -rf "$d"
printf '\n%s %s %s %s %s\n' "$nonce" "$rc" "${size:-0}" "${used:-0}" "${killed:-0}"
"""


@dataclass(frozen=True)
class WrapperResult:
    """What the trailer said, with the output before it."""

    output: bytes
    rc: int
    output_bytes: int
    repo_bytes: int
    disk_killed: bool


def parse(raw: bytes, nonce: str) -> WrapperResult | None:
    """Split the wrapper's output at its trailer; None when there is none (the wrapper was killed)."""
    marker = f"\n{nonce} ".encode()
    at = raw.rfind(marker)
    if at < 0:
        return None
    fields = raw[at + len(marker) :].split()
    try:
        rc, size, used, killed = (int(x) for x in fields[:4])
    except ValueError:
        return None
    return WrapperResult(raw[:at], rc, size, used, killed > 0)
