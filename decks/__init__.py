"""The example cases siloflow ships, installed as the package ``siloflow.decks`` (pyproject.toml maps
this folder there) and read through :mod:`siloflow.resources` (``siloflow example`` lists and copies
them). Not meant to be imported: it only makes the folder a package whose YAML files are resources."""
