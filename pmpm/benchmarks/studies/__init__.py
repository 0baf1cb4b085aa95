"""Studies: scripted parameter sweeps over the shipped cases (run them with ``python -m``).

- :mod:`pmpm.benchmarks.studies.frame_resolution`: the portal frame at several cell sizes, elastic and
  elastoplastic (docs/portal_frame.md, "Resolution study").
- :mod:`pmpm.benchmarks.studies.frame_fe`: the refinement study of the frame's plane-stress
  finite-element model, and MPM records analysed against it (docs/portal_frame.md, section 8).
"""
