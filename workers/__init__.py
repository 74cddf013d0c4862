"""What the Ray actors host: environments, the LLM gateway and its providers, episode workers.

Modules here may do I/O (read benchmark data, call models). Ray itself is imported only by the
actor modules, so environments and the gateway core can be used and tested without a cluster.
"""
