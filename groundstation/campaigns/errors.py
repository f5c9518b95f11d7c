"""The campaigns' errors, light enough for the command line to import before any simulator
code (the JIT mode is chosen after the parser is built)."""


class CampaignError(ValueError):
    """Unknown campaign or law, or a bad campaign parameter."""


class TuneError(CampaignError):
    """A bad tuning option or a study that does not match the command."""
