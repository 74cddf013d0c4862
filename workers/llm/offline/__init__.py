"""TEST DOUBLES: offline models served through litellm as the custom provider ``offline/``.

- ``offline/expert``  follows ``hints["expert_plan"]`` in the reply format of the agent style
  (:mod:`workers.llm.offline.expert`), with deterministic error injection;
- ``offline/random``  picks a random valid action (:mod:`workers.llm.offline.random_model`);
- ``offline/replay``  serves the recorded responses of an earlier run folder
  (:mod:`workers.llm.offline.replay`), so agent or report changes are regression-tested free.

They are registered as a litellm custom provider (:mod:`workers.llm.offline.provider`) so a
call to them takes the same path as a real provider: gateway, admission, ledger, records.
Every record they produce says ``test_double=True`` and names an ``offline/...`` model.
"""
