# Shared by run.sh and compare.sh (sourced): usage from the calling script's header, and die.
# shellcheck shell=bash

# Prints lines 2..$1 of the calling script (its header comment) without '# ' and exits 2.
usage() {
  sed -n "2,$1p" "${BASH_SOURCE[1]}" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
# Prints "<script>: message" to stderr and exits 1.
die() {
  echo "$(basename "${BASH_SOURCE[1]}"): $*" >&2
  exit 1
}
