"""Benchmarks behind `study bench ...`: measured figures for the README's Performance section.

Speed and memory targets are measured here, never asserted in timed tests.
"""
