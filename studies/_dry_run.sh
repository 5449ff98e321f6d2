# Shared by the studies' shell scripts: their --dry-run and the two commands it changes.
# Sourced, not run, before a script reads its own arguments (it takes --dry-run off them).
DRY=
[ "${1:-}" = --dry-run ] && { DRY=1; shift; }

# run COMMAND...: run it, or print it under --dry-run.
run() { if [ -n "$DRY" ]; then printf -v line '%q ' "$@"; echo "${line% }"; else "$@"; fi; }

# merge FROM INTO: FROM's rows appended to INTO, each row once. Two copies of a study (its parts
# on both cores) may merge at once: under flock where the system has it.
merge() {
  if [ -n "$DRY" ]; then echo "# merge $1 into $2"; return; fi
  touch "$2"
  if command -v flock >/dev/null; then
    flock "$2" sh -c 'cat "$1" >> "$2" && sort -u -o "$2" "$2"' merge "$1" "$2"
  else
    cat "$1" >> "$2" && sort -u -o "$2" "$2"
  fi
}
