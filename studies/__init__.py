"""Studies: scripted parameter sweeps over the shipped cases, run from a checkout with
``python -m studies.<name>`` (not installed with pmpm; they may use the test-only packages and
tests/verification's independent models).

- :mod:`studies.frame_resolution`: the portal frame at several cell sizes, elastic and
  elastoplastic (docs/portal_frame.md, "Resolution study").
- :mod:`studies.frame_fe`: the refinement study of the frame's plane-stress
  finite-element model, and MPM records analysed against it (docs/portal_frame.md, section 8).
- :mod:`studies.accuracy` (and ``accuracy_cfl``, ``accuracy_response``): error against wall
  time, ``pmpm bench accuracy`` (docs/accuracy.md).
- the others: one study each, named in the docs that quote their figures.
"""
