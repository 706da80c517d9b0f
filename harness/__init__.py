"""The development harness the tests and the benchmarks share: a real rob6 in processes, its clients and fakes.

Development only: no service image or package installs it, and the product (``shared/rob6``,
``services/*``) never imports it. It imports neither ``tests`` nor ``bench``; both import it
as ``harness.<module>`` from the repository root.
"""
