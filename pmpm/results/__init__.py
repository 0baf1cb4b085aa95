"""Results a structural engineer reads: section forces, support reactions, plastic hinges.

``sections`` (cuts across members: N, V, M), ``reactions`` (constraint forces of the essential
boundary conditions), ``recorder`` (their time histories during a run), ``hinges``
(utilisation M/Mp, N/Np and the times sections reach My and Mp), ``post`` (CSV files) and
``plots``. See docs/structural_results.md.
"""
