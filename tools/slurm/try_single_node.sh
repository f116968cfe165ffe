#!/usr/bin/env bash
# Tries tools/slurm/apply_tiles.sbatch for real on a single-node Slurm started on this machine
# (Debian's slurm-wlm and munge: `apt-get install slurm-wlm munge`), and checks that every
# output is byte-identical to `rigidcells apply` run here. Not part of CI; run as root from the
# repository root after `cargo build --release`:
#
#   bash tools/slurm/try_single_node.sh SCAN.las [TILES_PER_SIDE]
#
# It cuts the scan into tiles (`rigidcells` has no tiler: laspy does it, from
# target/ci-venv or $PYTHON), saves a field with `rigidcells deform --save-field`, submits
# the job array, waits, compares, and prints the times.
set -euo pipefail
scan=$(realpath "$1")
n=${2:-4}
repo=$(pwd)
bin=$repo/target/release/rigidcells
python=${PYTHON:-$repo/target/ci-venv/bin/python}
work=$(mktemp -d /tmp/rigidcells-slurm.XXXXXX)
host=$(hostname -s)
cpus=$(nproc)

# 1. munge and a one-node Slurm.
if [ ! -s /etc/munge/munge.key ]; then
  dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null
  chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
fi
mkdir -p /run/munge && chown munge:munge /run/munge
pgrep -x munged >/dev/null || su -s /bin/sh munge -c /usr/sbin/munged
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
cat > /etc/slurm/slurm.conf <<CONF
ClusterName=rigidcells
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
pgrep -x slurmctld >/dev/null || slurmctld
pgrep -x slurmd >/dev/null || slurmd
for _ in $(seq 30); do
  sinfo -h -o %T 2>/dev/null | grep -qE 'idle|mixed' && break
  sleep 1
done
scontrol update nodename="$host" state=resume 2>/dev/null || true
sinfo

# 2. Tiles, a field, and the reference outputs run here.
"$python" "$repo/tools/python/tiles.py" "$scan" "$work/tiles" "$n" > /dev/null
read -r x0 y0 z0 x1 y1 z1 < <("$python" -c "import laspy,sys; h=laspy.open(sys.argv[1]).header; print(*h.mins, *h.maxs)" "$scan")
cat > "$work/bend.toml" <<TOML
[[fixed]]
box = { min = [$x0, $y0, $z0], max = [$(echo "$x0 + 0.15 * ($x1 - $x0)" | bc -l), $y1, $z1] }
[[handle]]
box = { min = [$(echo "$x1 - 0.15 * ($x1 - $x0)" | bc -l), $y0, $z0], max = [$x1, $y1, $z1] }
translate = [0, 0, 5]
TOML
"$bin" deform "$scan" -o "$work/whole.las" --edit "$work/bend.toml" --save-field "$work/bend.field" --cells 5000 -q
ls "$work"/tiles/*.las > "$work/tiles.txt"
count=$(wc -l < "$work/tiles.txt")
mkdir -p "$work/ref"
start=$(date +%s.%N)
while read -r tile; do
  "$bin" apply "$work/bend.field" "$tile" -o "$work/ref/$(basename "$tile")" -q
done < "$work/tiles.txt"
here=$(echo "$(date +%s.%N) - $start" | bc -l)

# 3. The job array, and the comparison.
start=$(date +%s.%N)
cd "$work"
job=$(RIGIDCELLS="$bin" sbatch --parsable --array=0-$((count - 1)) --wait \
  "$repo/tools/slurm/apply_tiles.sbatch" "$work/bend.field" "$work/tiles.txt" "$work/slurm")
slurm=$(echo "$(date +%s.%N) - $start" | bc -l)
same=0
while read -r tile; do
  name=$(basename "$tile")
  cmp -s "$work/ref/$name" "$work/slurm/$name" && same=$((same + 1))
done < "$work/tiles.txt"
points=$("$python" -c "import laspy,sys; print(laspy.open(sys.argv[1]).header.point_count)" "$scan")
printf 'job %s: %d tiles, %s points; here one after another %.2f s, Slurm array %.2f s; identical outputs: %d of %d\n' \
  "$job" "$count" "$points" "$here" "$slurm" "$same" "$count"
[ "$same" -eq "$count" ]
