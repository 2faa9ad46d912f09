"""collie: human-in-the-loop guided skill discovery. Light, shared modules live here (task rules,
the oracle teacher's rule, wire schemas, the command line); processes live in trainer/, backend/,
labeling_ui/ and teacher/."""
