"""Tidy data frames from the study database, statistics, power, figures and reports."""
