"""The one error type for bad user input.

Every message is a single line, ``<where>: <field>: <problem>; <fix>``, so that
the command line can print it as it is and a test can match it.
"""


class InputError(ValueError):
    """Bad input from a user: a scene file, a grid, a command-line value, an EXR."""

    def __init__(self, where, field, problem, fix=None):
        self.where, self.field, self.problem, self.fix = str(where), field, problem, fix
        text = f"{where}: {field}: {problem}" if field else f"{where}: {problem}"
        if fix:
            text += f"; {fix}"
        super().__init__(" ".join(text.split()))


class EnvironmentProblem(RuntimeError):
    """A system component is missing: an LLVM for Mitsuba, an OpenGL 4.3 context.

    The message is one line that names the component and how to install it.
    """


class ResultRefused(RuntimeError):
    """A renderer refused its own result: a self-check (e.g. the rivals' spot check against their
    NumPy twin, :mod:`dipole_gl.check`) found it wrong.

    The message is one line naming the check, the value and the tolerance; the command line
    prints it and exits with status 1, a sweep records the configuration as failed.
    """
