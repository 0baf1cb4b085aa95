"""The host a benchmark ran on: its CPU model, as the benchmarks print it beside their figures
(a ratio to a peer depends on the CPU: docs/performance.md)."""
import platform

__all__ = ["cpu_model"]


def cpu_model():
    """The CPU's model name (``/proc/cpuinfo``; the family and model numbers where the name is
    generic, as on some virtual machines: "AMD EPYC (family 26, model 2)")."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if not line.strip():
                    break  # the first processor is enough
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        return platform.processor() or platform.machine()
    name = fields.get("model name", platform.processor() or platform.machine())
    if "family" not in name.lower() and "cpu family" in fields:
        name += f" (family {fields['cpu family']}, model {fields.get('model', '?')})"
    return name
