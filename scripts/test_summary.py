#!/usr/bin/env python3
"""Sums the JUnit XML results of `catkin_make run_tests` and prints `N passed, N failed`.

Counts every test case of the gtest binaries (gtest-*.xml) and of the gtests that rostest ran
(rosunit-*.xml). A rostest's own file (rostest-*.xml) repeats its test cases, so only its errors
and failures are counted (a node that crashed, a test that never reported). A result file that
does not parse, or a test directory with no result at all, counts as a failure. Exits non-zero on
any failure.
"""
import os
import sys
import xml.etree.ElementTree as ET


def cases(root):
    return root.iter('testcase')


def main(argv):
    if len(argv) != 2:
        print('usage: test_summary.py RESULTS_DIR', file=sys.stderr)
        return 2
    results_dir = argv[1]
    passed = failed = skipped = 0
    failures = []
    files = []
    for dirpath, _, names in os.walk(results_dir):
        files += [os.path.join(dirpath, n) for n in sorted(names) if n.endswith('.xml')]
    for path in files:
        name = os.path.basename(path)
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as e:
            failed += 1
            failures.append('%s: unreadable result (%s)' % (name, e))
            continue
        if name.startswith('rostest-'):
            for tc in cases(root):
                if tc.find('failure') is not None or tc.find('error') is not None:
                    failed += 1
                    failures.append('%s: %s' % (name, tc.get('name')))
            continue
        for tc in cases(root):
            label = '%s: %s.%s' % (name, tc.get('classname'), tc.get('name'))
            if tc.find('failure') is not None or tc.find('error') is not None:
                failed += 1
                failures.append(label)
            elif tc.find('skipped') is not None or tc.get('status') == 'notrun':
                skipped += 1
            else:
                passed += 1
    if not files:
        failed += 1
        failures.append('no test result files under %s' % results_dir)
    for f in failures:
        print('FAILED ' + f)
    line = '%d passed, %d failed' % (passed, failed)
    if skipped:
        line += ', %d skipped' % skipped
    print(line)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
