#!/usr/bin/env bash
# One-command setup for a fresh Debian (bookworm) machine, run as root from the repo root.
#   bash scripts/setup.sh            the default stack in .venv: Python 3.11, CPU torch 2.13.0, NumPy 1.26
#                                    (every committed result was made on it)
#   bash scripts/setup.sh lerobot    the LeRobot stack in .venv-lerobot: Python 3.12, NumPy 2.2, torch 2.11
#                                    from PyPI, LeRobot 0.6.1 and the lerobot_env_softvt plugin (lerobot-train,
#                                    lerobot-eval --env.type=softvt); beside the default, not instead of it
# Each stack installs against its constraints file (scripts/constraints-<stack>.txt): the versions it was
# verified with.
#   1. Vulkan software rendering: libvulkan1 + mesa-vulkan-drivers 25.x from bookworm-backports
#      (stable's mesa 22.3 lavapipe lacks descriptorBindingPartiallyBound; SAPIEN then finds
#      no rendering device). The backports suite uses the mirror URI the machine's own Debian
#      sources already use.
#   2. A virtual environment in .venv with torch 2.13.0 (CPU) installed first, then the package and the
#      campaign (campaign/: the Diffusion Policy baselines and their studies).
#      SOFTVT_TORCH_INDEX_URL: the index torch comes from. Unset, pip's own configuration decides
#      (on this project's machines a local CPU wheel); on a machine whose default is PyPI's
#      multi-GB CUDA build (Linux x86_64), point it at PyTorch's CPU wheel index:
#        SOFTVT_TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu bash scripts/setup.sh
#      Set it for the first run: pip keeps a torch 2.13.0 already in the venv, whatever its build.
#   3. Warm the Warp kernel cache so the first episode does not pay ~40 s of compilation.
# Idempotent: a second run checks each step and skips it.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
STACK=${1:-default}
case "$STACK" in
  default) VENV=${SOFTVT_VENV:-$ROOT/.venv} ;;
  lerobot) VENV=${SOFTVT_LEROBOT_VENV:-$ROOT/.venv-lerobot} ;;
  *) echo "setup: unknown stack '$STACK'; run 'bash scripts/setup.sh' (default) or 'bash scripts/setup.sh lerobot'" >&2; exit 2 ;;
esac
CONSTRAINTS=$ROOT/scripts/constraints-$STACK.txt
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"

log() { printf '[setup] %s\n' "$*"; }

# A full disk fails pip midway with "[Errno 28] No space left on device" and a half-built venv: check
# first, before a new venv is made (an update of an existing one needs little). Measured (2026-12-05):
# the default venv 3.3 GB; the LeRobot one 7.4 GB (torch's CUDA build and its nvidia wheels), with
# about 3 GB of pip's unpacked wheels in the temporary directory meanwhile. A CI run once failed in
# the LeRobot install with ENOSPC beside a campaign's data caches.
need_space() {
  local gb=$1 dir tmp=${TMPDIR:-/tmp} avail
  [ -x "$VENV/bin/python" ] && return 0
  dir=$(dirname "$VENV"); while [ ! -d "$dir" ]; do dir=$(dirname "$dir"); done
  free_gb() { df -Pk "$1" | awk 'NR == 2 {print int($4 / 1048576)}'; }
  avail=$(free_gb "$dir")
  # pip's temporary files count against the venv's filesystem when they share it, else against their own
  if [ -d "$tmp" ] && [ "$(stat -c %d "$tmp")" != "$(stat -c %d "$dir")" ] && [ "$(free_gb "$tmp")" -lt 3 ]; then
    echo "setup: $(free_gb "$tmp") GB free in $tmp (TMPDIR), pip needs about 3 GB there; free some or point TMPDIR elsewhere, and re-run" >&2
    exit 1
  fi
  if [ "$avail" -lt "$gb" ]; then
    echo "setup: $avail GB free on $dir, the $STACK stack needs about $gb GB to install; free some space" \
      "(e.g. a campaign's data caches in \$SOFTVT_RUNS_DIR, rebuilt on demand) and re-run" >&2
    exit 1
  fi
}

# ---------------------------------------------------------------- 1. apt
codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-bookworm}")
mesa_major=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null | sed -E 's/^([0-9]+:)?([0-9]+).*/\2/' || true)
if [ "${mesa_major:-0}" -ge 25 ] 2>/dev/null && dpkg-query -W libvulkan1 >/dev/null 2>&1; then
  log "mesa-vulkan-drivers ${mesa_major}.x already installed"
else
  bp=/etc/apt/sources.list.d/${codename}-backports.sources
  if ! grep -rqs "${codename}-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
    # The mirror URI of the machine's own main Debian suite (deb822 stanzas or one-line form).
    uri=$( { awk -v s="$codename" 'BEGIN{RS=""} $0 ~ "Suites:[^\n]*(^|[ \t])" s "([ \t]|$)" \
               { if (match($0, /URIs:[ \t]*[^ \t\n]+/)) { u=substr($0,RSTART,RLENGTH); sub(/URIs:[ \t]*/,"",u); print u } }' \
               /etc/apt/sources.list.d/*.sources 2>/dev/null || true
             awk -v s="$codename" '$1=="deb" && $3==s {print $2}' /etc/apt/sources.list 2>/dev/null || true
           } | head -n 1)
    [ -n "$uri" ] || { echo "setup: no Debian mirror found in /etc/apt sources; add one, then re-run" >&2; exit 1; }
    log "adding ${codename}-backports from $uri"
    printf 'Types: deb\nURIs: %s\nSuites: %s-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
      "$uri" "$codename" | $SUDO tee "$bp" >/dev/null
  fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq -t "${codename}-backports" \
    libvulkan1 mesa-vulkan-drivers >/dev/null
  log "installed mesa-vulkan-drivers $(dpkg-query -W -f='${Version}' mesa-vulkan-drivers)"
fi

# ---------------------------------------------------------------- 2. venv + pip
stamp="$VENV/.softvt-installed"
want=$(cat pyproject.toml scripts/setup.sh "$CONSTRAINTS" plugins/lerobot_env_softvt/pyproject.toml campaign/pyproject.toml \
  | sha256sum | cut -c1-16)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  log "virtual environment $VENV up to date"
elif [ "$STACK" = default ]; then
  need_space 6
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  # CPU torch first: otherwise mani-skill's torch requirement pulls a CUDA build.
  if [ -n "${SOFTVT_TORCH_INDEX_URL:-}" ]; then
    log "torch from $SOFTVT_TORCH_INDEX_URL"
    "$VENV/bin/python" -m pip install -q torch==2.13.0 --index-url "$SOFTVT_TORCH_INDEX_URL"
  else
    "$VENV/bin/python" -m pip install -q torch==2.13.0
  fi
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" -e ".[dev,remote]"
  # The campaign's distribution beside it: the Diffusion Policy baselines (the diffusion_policy policy
  # kind every committed policy file needs) and the studies.
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" -e campaign
  echo "$want" > "$stamp"
  log "installed the package and the campaign into $VENV"
else
  need_space 12
  # LeRobot 0.6.1 needs Python >= 3.12: the machine's python3.12, else pyenv's.
  # (A pyenv shim on PATH may name python3.12 and still refuse to run it: each candidate is tried.)
  py=""
  for cand in "$HOME"/.pyenv/versions/3.12*/bin/python3.12 /root/.pyenv/versions/3.12*/bin/python3.12 "$(command -v python3.12 || true)"; do
    if [ -n "$cand" ] && [ -x "$cand" ] && "$cand" -c 'import sys, venv; assert sys.version_info[:2] == (3, 12)' 2>/dev/null; then
      py=$cand; break
    fi
  done
  [ -n "$py" ] || { echo "setup: the LeRobot stack needs Python 3.12 (python3.12 on PATH or pyenv's); install it (e.g. 'pyenv install 3.12') and re-run" >&2; exit 1; }
  log "Python 3.12 for the LeRobot stack: $py"
  [ -x "$VENV/bin/python" ] || "$py" -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  # torch 2.11 for Python 3.12 comes from the package index (LeRobot 0.6.1 needs torch < 2.12): a CUDA build
  # that runs on the CPU, about 5 GB installed.
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" "lerobot[dataset,training,diffusion]==0.6.1" -e ".[dev]"
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" -e plugins/lerobot_env_softvt
  # The campaign too (LeRobot brings diffusers): its tests and the committed policy files run on this stack.
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" -e campaign
  echo "$want" > "$stamp"
  log "installed LeRobot 0.6.1, the package, its plugin and the campaign into $VENV"
fi

# ---------------------------------------------------------------- 3. Warp kernel cache
"$VENV/bin/python" -m mani_skill_softvt.cli.warmup
log "done ($STACK stack). Activate with: source $VENV/bin/activate"
