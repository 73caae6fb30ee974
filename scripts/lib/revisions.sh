# Sourced by scripts/logs_identical.sh and scripts/bench_before_after.sh: a revision checked out
# in a detached worktree of its own, for builds side by side with the working tree. The caller
# sets WORK (the directory holding one worktree per side) and ROOT (the repository).

log() { echo "$*" >&2; }

# Check out REV in a detached worktree at $WORK/<side> (created once, then moved to REV); print
# its path.
checkout() {
  local side=$1 rev=$2 dir=$WORK/$1 sha
  sha=$(git rev-parse --verify "$rev^{commit}") || { log "unknown revision: $rev"; exit 2; }
  if [ ! -e "$dir/.git" ]; then
    git worktree prune
    git worktree add -q --detach "$dir" "$sha" >&2
  else
    if [ -n "$(git -C "$dir" status --porcelain --untracked-files=no)" ]; then
      log "$dir has local changes; remove it (git worktree remove --force $dir) or clean it"
      exit 2
    fi
    git -C "$dir" checkout -q --detach "$sha"
  fi
  echo "$dir"
}

# One side of a comparison: REV empty is the working tree (its own target dir), else REV checked
# out by `checkout`. Sets the caller's `src` (source dir), `tdir` (target dir) and `desc` (what it
# is, for the log); the caller declares them local.
resolve_side() {
  local side=$1 rev=$2
  if [ -z "$rev" ]; then
    src=$ROOT
    tdir=${CARGO_TARGET_DIR:-$ROOT/target}
    desc="working tree ($(git rev-parse --short HEAD))"
    [ -z "$(git status --porcelain --untracked-files=no)" ] || desc="working tree ($(git rev-parse --short HEAD) + changes)"
  else
    src=$(checkout "$side" "$rev")
    tdir=$WORK/$side-target
    desc="$rev ($(git rev-parse --short "$rev^{commit}"))"
  fi
}
