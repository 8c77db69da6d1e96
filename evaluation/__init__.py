"""evaluation: closed-loop tracking against the paper's tables (`vtr eval`), the demo (`vtr demo`), their
scoring, reports and plots. Installed as ``vtr.evaluation``; it runs the runtime's Repeater and reads the
benchmarks' result files, and nothing in the libraries imports it."""
