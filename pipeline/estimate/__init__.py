"""estimate subpackage."""
