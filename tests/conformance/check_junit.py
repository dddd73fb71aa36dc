"""A JUnit XML file gyrobench wrote parses with third-party JUnit readers.

Usage: check_junit.py FILE
junitparser reads every suite and case (failures and errors with their
messages); xmlschema validates the file against the common JUnit schema
(tests/conformance/junit.xsd, the Jenkins/Ant form CI servers read).
"""
import os
import sys

import junitparser
import xmlschema


def main():
    path = sys.argv[1]
    here = os.path.dirname(os.path.abspath(__file__))
    schema = xmlschema.XMLSchema(os.path.join(here, "junit.xsd"))
    schema.validate(path)
    xml = junitparser.JUnitXml.fromfile(path)
    suites = list(xml)
    assert suites, "no testsuite"
    cases = 0
    for suite in suites:
        for case in suite:
            cases += 1
            for r in case.result:
                assert r.message, f"{suite.name} / {case.name}: a {type(r).__name__} without a message"
    print(f"ok: {len(suites)} suites, {cases} cases, valid against junit.xsd")


if __name__ == "__main__":
    main()
