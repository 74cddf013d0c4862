-- The paper section's SWE-bench Verified settings: per arm (model label x arm label), the
-- temperatures its settings carried (method_config's temperature; NULL when none was set), over the
-- rows the paper cells count (paper_scoped, scope 'all'). The paper ran GPT-4.1 at temperature 0;
-- paper_cells.sql does not carry the temperature, so the main table reads it here, and only when a
-- run has SWE-bench Verified cells.
SELECT model_label, arm_label,
  list(DISTINCT TRY_CAST(json_extract_string(method_config, '$.temperature') AS DOUBLE)
       ORDER BY TRY_CAST(json_extract_string(method_config, '$.temperature') AS DOUBLE) NULLS LAST) AS temperatures
FROM paper_scoped
WHERE scope = 'all' AND benchmark = 'swe-verified'
GROUP BY ALL
ORDER BY ALL;
