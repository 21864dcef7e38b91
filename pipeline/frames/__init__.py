"""frames subpackage."""
