"""Human-readable reports (Markdown and HTML) next to the JSON outputs."""
