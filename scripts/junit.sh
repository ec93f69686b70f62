# The cases of the shell checks of make test (scripts/check_*.sh) and their JUnit XML, which catkin's
# run_tests reads. Source it, then for each case
#   record CASE pass|fail MESSAGE
# and at the end (prints a line per case, writes FILE when given, returns non-zero on a failure):
#   finish_checks LABEL SUITE [FILE]
# write_junit FILE SUITE CASE... writes the XML of the cases in status[CASE] and message[CASE].
declare -a names
declare -A status message
record() {  # name, pass|fail, message
  names+=("$1")
  status[$1]=$2
  message[$1]=$3
}

finish_checks() {  # label, suite, [junit file]
  local name failures=0
  for name in "${names[@]}"; do
    echo "$1, $name: ${status[$name]}: ${message[$name]}"
    [ "${status[$name]}" = pass ] || failures=$((failures + 1))
  done
  [ -n "${3:-}" ] && write_junit "$3" "$2" "${names[@]}"
  [ "$failures" -eq 0 ]
}

write_junit() {
  local file=$1 suite=$2 name failures=0
  shift 2
  for name in "$@"; do [ "${status[$name]}" = pass ] || failures=$((failures + 1)); done
  mkdir -p "$(dirname "$file")"
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"$suite\" tests=\"$#\" failures=\"$failures\" errors=\"0\">"
    for name in "$@"; do
      echo "  <testcase classname=\"$suite\" name=\"$name\">"
      if [ "${status[$name]}" != pass ]; then
        printf '    <failure message="%s"/>\n' "$(sed 's/&/\&amp;/g; s/"/\&quot;/g; s/</\&lt;/g' <<<"${message[$name]}")"
      fi
      echo "  </testcase>"
    done
    echo "</testsuite>"
  } >"$file"
}
