"""The one exception type a user of handcap needs to catch."""


class HandcapError(Exception):
    """A user mistake or unusable input: bad file, wrong units, unknown name.

    The message is one line that says what is wrong and, where possible, how to
    mend it. The command line prints it and exits with code 2.
    """
