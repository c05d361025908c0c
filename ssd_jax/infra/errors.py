"""The project's own errors: what a user can fix (a bad file, cloud, config or checkpoint).

Every command reports these in one line naming the problem and exits non-zero (`cli.run`,
the one place that catches them); any other exception is a bug and keeps its traceback.
Each subclasses ValueError as well, so code that catches a ValueError from a library call
keeps catching them.
"""


class UserError(ValueError):
  """Bad input a user can fix; the message names what and where, in one line."""


# What a command reports in one line and exit status 1 (`cli.run`): the project's
# UserErrors (a ValueError), and the ValueError or FileNotFoundError that a library
# function raises for a bad argument or a path that does not exist.
REPORTED = (ValueError, FileNotFoundError)
