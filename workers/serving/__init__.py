"""The Ray Serve deployments a sweep starts for the models it serves itself (``models[].serve``).

- :mod:`workers.serving.test_double`: TEST DOUBLE, an OpenAI-compatible chat endpoint answering
  like the ``offline/`` test doubles, so the serving path (deploy, route, replicas, a replica
  lost mid-run, cost) is tested without weights or a GPU;
- :mod:`workers.serving.llama_cpp`: a deployment around ``llama_cpp.server`` for GGUF weights.

vLLM and SGLang are deployed through ``ray.serve.llm`` by :mod:`pipeline.serving.engines`.
"""
