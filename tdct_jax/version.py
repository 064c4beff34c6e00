"""The package version, one place for the package, the command line and sweep fingerprints."""

__version__ = "0.1.0"
