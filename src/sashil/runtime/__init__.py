"""The real-time side: clocks and the fixed-rate control loop (owns time and I/O)."""
