"""The firmware's record formatting (firmware/sds_arduino/protocol.h) against the Python
reference: compiled with the host's compiler, and for the ATmega2560 when avr-g++ exists."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from sds_arduino.protocol import FIELDS, Record, format_record, parse_line

PROGRAM = r"""
#include <stdio.h>
#include "protocol.h"
int main(void) {
  unsigned long seq, t; char kind[4]; int count; long v[4];
  while (scanf("%lu %lu %3s %d %ld %ld %ld %ld", &seq, &t, kind, &count,
               &v[0], &v[1], &v[2], &v[3]) == 8) {
    int32_t values[4] = {(int32_t)v[0], (int32_t)v[1], (int32_t)v[2], (int32_t)v[3]};
    char line[SDS_MAX_LINE + 1];
    if (sds_format(line, (uint32_t)seq, (uint32_t)t, kind, values, (uint8_t)count) == 0) return 1;
    fputs(line, stdout);
  }
  return 0;
}
"""


def records(count: int) -> list[Record]:
    rng = np.random.default_rng(4)
    kinds = list(FIELDS)
    out = [Record(2**32 - 1, 2**32 - 1, "IMU", (-2**31, 2**31 - 1, 0)),
           Record(0, 0, "TOF", (8190, 1))]
    for _ in range(count):
        kind = kinds[rng.integers(len(kinds))]
        out.append(Record(int(rng.integers(2**32)), int(rng.integers(2**32)), kind,
                          tuple(int(v) for v in rng.integers(-16384, 16384, len(FIELDS[kind])))))
    return out


def test_firmware_lines_equal_the_python_reference(repo: Path, tmp_path: Path) -> None:
    compiler = shutil.which("g++") or shutil.which("c++")
    if compiler is None:
        pytest.skip("no host C++ compiler")
    source = tmp_path / "format.cpp"
    source.write_text(PROGRAM)
    binary = tmp_path / "format"
    subprocess.run([compiler, "-std=c++11", "-Wall", "-Werror", "-I",
                    str(repo / "firmware" / "sds_arduino"), str(source), "-o", str(binary)],
                   check=True, capture_output=True)
    sample = records(2000)
    text = "".join(f"{r.seq} {r.t_us} {r.kind} {len(r.values)} "
                   + " ".join(map(str, (*r.values, 0, 0, 0, 0)[:4])) + "\n" for r in sample)
    done = subprocess.run([str(binary)], input=text.encode(), capture_output=True, check=True)
    lines = done.stdout.decode("ascii").splitlines(keepends=True)   # CR LF kept
    assert lines == [format_record(r) for r in sample]
    assert [parse_line(line) for line in lines] == sample


def test_firmware_protocol_compiles_for_the_atmega2560(repo: Path, tmp_path: Path) -> None:
    compiler = shutil.which("avr-g++")
    if compiler is None:
        pytest.skip("avr-g++ not installed (Debian: gcc-avr avr-libc); CI installs it")
    source = tmp_path / "check.cpp"
    source.write_text('#include "protocol.h"\n'
                      "char line[SDS_MAX_LINE + 1];\n"
                      "int main(void) { int32_t v[3] = {-16000, 0, 16000};\n"
                      "  return (int)sds_format(line, 4294967295UL, 4294967295UL,"
                      ' "IMU", v, 3); }\n')
    subprocess.run([compiler, "-mmcu=atmega2560", "-Os", "-std=c++11", "-Wall", "-Werror", "-I",
                    str(repo / "firmware" / "sds_arduino"), str(source), "-o",
                    str(tmp_path / "check.elf")], check=True, capture_output=True)
    assert (tmp_path / "check.elf").stat().st_size > 0
