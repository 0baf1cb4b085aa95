"""Studies: scripted parameter sweeps over the shipped cases (run them with ``python -m``).

- :mod:`pmpm.benchmarks.studies.frame_resolution`: the portal frame at several cell sizes, elastic and
  elastoplastic (docs/portal_frame.md, "Resolution study").
"""
