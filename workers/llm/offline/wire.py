"""How a call's hints reach the offline test doubles: one key of litellm's ``metadata``.

Why its own module: :mod:`workers.llm.calling` writes the key and
:mod:`workers.llm.offline.provider` reads it; the provider is registered from the module
calling imports, so neither may import the other for a constant.
"""

#: litellm metadata key carrying hints to the offline test doubles (never sent to providers)
OFFLINE_METADATA_KEY = "recap_offline"
