# JUnit XML for the shell checks of make test (scripts/check_*.sh), which catkin's run_tests reads.
# Source it, fill the associative arrays status[CASE] (pass | fail) and message[CASE], then:
#   write_junit FILE SUITE CASE...
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
