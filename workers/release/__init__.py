"""The authors' released prompt and demonstration files (``prompts: release``).

Our prompts and demonstrations are our own text, and stay the default. A method entry with
``prompts: release`` instead reads the authors' files at run time, from a folder that
``recap data fetch recap-release`` fills from the pinned commit of their repository (checked
against ``pipeline/manifests/recap-release.sha256``): nothing of theirs is stored in this
repository. :mod:`.folder` declares the folder, :mod:`.texts` extracts what each method shows.
"""
