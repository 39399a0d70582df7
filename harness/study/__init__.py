"""The accuracy study (``sslpv-harness study``): one command from a declarative study file to the map.

``spec`` reads the study file; ``run`` runs it through the sweep (resumable, the result cache) and
writes the study folder; ``table`` turns the store into one row per (scene, method, setting);
``headline`` picks each family's best setting per budget and judges the differences; ``limits``
measures what limits SSLPV per scene; ``figures`` draws the plots; ``page`` writes ``index.html``;
``docs`` writes ``docs/results.md``.
"""
