"""Reporting of the hard cases: the energy each case lost (tests/hard/test_hard_cases.py fills
``config.hard_case_losses``) printed in the terminal summary, pass or fail."""


def pytest_terminal_summary(terminalreporter, config):
    losses = getattr(config, "hard_case_losses", None)
    if not losses:
        return
    terminalreporter.write_sep("-", "hard cases: energy lost (exact-work balance, of the largest energy in play)")
    for name, row in losses.items():
        terminalreporter.write_line(f"{name:26s} " + ", ".join(f"{k} {v:.3%}" for k, v in row.items()))
