"""The models a sweep serves itself on its Ray cluster (``models[].serve``), with Ray Serve.

- :mod:`pipeline.serving.checks`: preflight (engine installed, weights present, the cluster's
  GPUs and CPUs enough for the replicas), each refusal one line before anything starts;
- :mod:`pipeline.serving.engines`: the Serve application of each engine;
- :mod:`pipeline.serving.service`: started as a run service before the first unit, ready when
  every replica answers, named to the gateway as an OpenAI-compatible ``api_base`` with
  ``replicas x max_in_flight`` calls outstanding, stopped at the end of the session, on
  Ctrl-C, and by the next session of the run when a killed driver left it;
- :mod:`pipeline.serving.cost`: the replica-hours held, charged to the run's ledger as they
  accrue and attributed to the model's calls by their tokens;
- :mod:`pipeline.serving.throughput`: what ``recap estimate`` prices a served model by - its
  output tokens/s, from the sweep (``serve.tokens_per_s``) or measured by a short probe.

The gateway's in-flight limit for a served model adapts to its replicas' latency and queue
(:mod:`workers.gateway.adaptive`; the queue read per engine: :func:`pipeline.serving.service.queue_source`,
:mod:`workers.gateway.queue_feed`).
"""
