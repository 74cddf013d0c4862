"""The product around the method: sweep specs, units of work, the Ray driver, resume, the CLI.

A researcher writes one sweep file (:mod:`pipeline.spec`); it expands into units of work with
stable content hashes (:mod:`pipeline.units`); the driver (:mod:`pipeline.driver`) runs them on
Ray through a pool of episode workers, the LLM gateway and one sink actor, writing queryable
Parquet tables under the run folder (:mod:`pipeline.store`); ``recap resume`` finishes whatever a
crash left (:mod:`pipeline.resume`). Dependencies point one way: pipeline -> workers -> recap.
"""
