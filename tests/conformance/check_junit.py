"""A JUnit XML file gyrobench wrote parses with third-party JUnit readers.

Usage: check_junit.py FILE [SUITES]
junitparser reads every suite and case (failures and errors with their
messages); xmlschema validates the file against the JUnit schema of Jenkins' xUnit
plugin (junit-10.xsd, the common schema CI servers read; `.ci/run` takes it
from pytest's source distribution on PyPI, which carries it for the same
check, and names it in GYROBENCH_JUNIT_XSD) and against the stricter Ant
form in tests/conformance/junit.xsd (typed counts and timestamps).
"""
import os
import sys

import junitparser
import xmlschema


def main():
    path = sys.argv[1]
    here = os.path.dirname(os.path.abspath(__file__))
    schemas = [os.path.join(here, "junit.xsd")]
    common = os.environ.get("GYROBENCH_JUNIT_XSD")
    if common:
        schemas.append(common)
    elif os.environ.get("CI"):
        sys.exit("CI validates against Jenkins' junit-10.xsd: set GYROBENCH_JUNIT_XSD")
    for xsd in schemas:
        xmlschema.XMLSchema(xsd).validate(path)
    xml = junitparser.JUnitXml.fromfile(path)
    suites = list(xml)
    assert suites, "no testsuite"
    cases = 0
    for suite in suites:
        for case in suite:
            cases += 1
            for r in case.result:
                assert r.message, f"{suite.name} / {case.name}: a {type(r).__name__} without a message"
    if len(sys.argv) > 2:
        want = int(sys.argv[2])
        assert len(suites) == want, f"{len(suites)} suites, expected {want}"
    names = ", ".join(os.path.basename(x) for x in schemas)
    print(f"ok: {len(suites)} suites, {cases} cases, valid against {names}")


if __name__ == "__main__":
    main()
