#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The link checker on a small fixture: it passes the fixture as committed and
fails, naming the file, the line and the reference, on each kind of dangling
reference planted into a copy of it. A checker that cannot fail would pass the
real docs whatever they say."""
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
CHECKER = os.path.join(HERE, "check_links.py")
FIXTURE = os.path.join(HERE, "fixture")


def run(root, allow=True):
    files = [os.path.join(root, "README.md")] + sorted(
        os.path.join(root, "docs", f) for f in os.listdir(os.path.join(root, "docs")))
    cmd = [sys.executable, CHECKER, "--root", root] + (
        ["--allow", os.path.join(root, "allowed.list")] if allow else []) + files
    p = subprocess.run(cmd, capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


class Checker(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="check_links.")
        self.root = os.path.join(self.tmp, "repo")
        shutil.copytree(FIXTURE, self.root)

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def append(self, rel, text):
        with open(os.path.join(self.root, rel), "a", encoding="utf-8") as f:
            f.write(text)

    def fails_with(self, *expected):
        code, out = run(self.root)
        self.assertEqual(code, 1, out)
        for e in expected:
            self.assertIn(e, out)
        return out

    def test_the_fixture_passes(self):
        code, out = run(self.root)
        self.assertEqual(code, 0, out)

    def test_a_link_to_a_missing_file(self):
        self.append("docs/guide.md", "\nSee [gone](gone.md).\n")
        self.fails_with("docs/guide.md:26: link 'gone.md': no such file")

    def test_a_link_to_a_missing_anchor(self):
        self.append("README.md", "\n[units](docs/guide.md#units)\n")
        self.fails_with("README.md:8: link 'docs/guide.md#units': docs/guide.md has no heading with anchor '#units'")

    def test_an_anchor_in_the_same_file(self):
        self.append("docs/other.md", "\n[where](#nowhere)\n")
        self.fails_with("docs/other.md:8: link '#nowhere'")

    def test_a_link_that_leaves_the_repository(self):
        # The file exists on this machine, beside the fixture; a clone has nothing there.
        with open(os.path.join(self.tmp, "beside.md"), "w") as f:
            f.write("# beside\n")
        self.append("docs/guide.md", "\n[beside](../../beside.md)\n")
        self.fails_with("link '../../beside.md' leaves the repository")

    def test_a_reference_to_the_private_folder(self):
        self.append("docs/other.md", "\nThe equations are in shared/spec/effects.md.\n")
        self.fails_with("docs/other.md:8: refers to the private folder")

    def test_the_private_folder_inside_a_code_block_too(self):
        self.append("docs/other.md", "\n```\n# (../shared/spec/machine.md)\n```\n")
        self.fails_with("docs/other.md:9: refers to the private folder")

    def test_a_file_named_in_text_that_does_not_exist(self):
        self.append("docs/other.md", "\nThe frame is in `machine.md`; the code in src/gone.cpp.\n")
        self.fails_with("docs/other.md:8: 'machine.md' is named but", "'src/gone.cpp' is named but")

    def test_without_its_allow_list_the_optional_folder_fails(self):
        code, out = run(self.root, allow=False)
        self.assertEqual(code, 1, out)
        self.assertIn("README.md:6: refers to the private folder", out)

    def test_an_allow_list_entry_that_matches_nothing(self):
        self.append("allowed.list", "docs/other.md | no such text | a stale entry\n")
        self.fails_with("allowed.list:3: allow-list entry matches nothing")

    def test_the_source_scan_finds_a_message_that_points_at_the_private_folder(self):
        cmd = [sys.executable, CHECKER, "--root", self.root, "--sources"]
        p = subprocess.run(cmd, capture_output=True, text=True)
        self.assertEqual(p.returncode, 0, p.stdout)
        self.append("src/main.cpp", 'const char* m = "see shared/spec/effects.md for the names";\n')
        p = subprocess.run(cmd, capture_output=True, text=True)
        self.assertEqual(p.returncode, 1, p.stdout)
        self.assertIn("src/main.cpp:2: refers to the private folder", p.stdout)


if __name__ == "__main__":
    unittest.main(verbosity=2)
