#!/usr/bin/env python3
"""Sums the JUnit XML results of `catkin_make run_tests` and prints `N passed, N failed`.

Counts every test case of the gtest binaries (gtest-*.xml) and of the gtests that rostest ran
(rosunit-*.xml). A rostest's own file (rostest-*.xml) repeats its test cases, so only its errors
and failures are counted (a node that crashed, a test that never reported). A result file that
does not parse, or a test directory with no result at all, counts as a failure. Exits non-zero on
any failure.

With --sanitizer-logs DIR (make test-asan, test-tsan), every sanitizer report file in DIR counts as a
failure too: the tests' own and those of the ROS nodes that rostest launched, which no JUnit file
shows (a node's report does not fail its test by itself, a leak report comes after the results).
"""
import os
import sys
import xml.etree.ElementTree as ET


def cases(root):
    return root.iter('testcase')


SANITIZER_MARKERS = ('ERROR: AddressSanitizer', 'ERROR: LeakSanitizer', 'WARNING: ThreadSanitizer',
                     'ERROR: ThreadSanitizer', 'runtime error:', 'ERROR: UndefinedBehaviorSanitizer')


def sanitizer_reports(log_dir):
    """The report files that the sanitizers wrote under log_dir (log_path=DIR/NAME, log_exe_name=1: one
    file per process, NAME.<executable>.<pid>), each with its SUMMARY lines (or its first marker line)."""
    reports = []
    if not os.path.isdir(log_dir):
        return reports
    for name in sorted(os.listdir(log_dir)):
        path = os.path.join(log_dir, name)
        if not os.path.isfile(path):
            continue
        with open(path, errors='replace') as f:
            text = f.read()
        if not any(m in text for m in SANITIZER_MARKERS):
            continue
        lines = [l.strip() for l in text.splitlines()]
        summary = [l for l in lines if l.startswith('SUMMARY:')]
        if not summary:
            summary = [next(l for l in lines if any(m in l for m in SANITIZER_MARKERS))]
        reports.append((path, summary))
    return reports


def main(argv):
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('results', nargs='+', help='JUnit result directories (catkin build/test_results)')
    ap.add_argument('--sanitizer-logs', action='append', default=[], metavar='DIR',
                    help='a directory of sanitizer report files (ASAN/UBSAN/TSAN_OPTIONS log_path): '
                         'every report in it, from a test or a node it launched, counts as a failure')
    args = ap.parse_args(argv[1:])
    passed = failed = skipped = 0
    failures = []
    for results_dir in args.results:
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
    for log_dir in args.sanitizer_logs:
        for path, summary in sanitizer_reports(log_dir):
            failed += 1
            failures.append('sanitizer report %s: %s' % (path, ' | '.join(summary)))
    for f in failures:
        print('FAILED ' + f)
    line = '%d passed, %d failed' % (passed, failed)
    if skipped:
        line += ', %d skipped' % skipped
    print(line)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
