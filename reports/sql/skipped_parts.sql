-- Part files left out because they could not be read (truncated or corrupt).
SELECT run_dir, "table", path, error FROM bad_parts ORDER BY run_dir, "table", path;
