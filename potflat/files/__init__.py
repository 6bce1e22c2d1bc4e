"""The file layer: each stage's runner with its file names and sidecars
(:mod:`.rollout_stage`, :mod:`.relax_stage`, :mod:`.bake_stage`; the names in
:mod:`.names`), one scan through all stages (:mod:`.pipeline`), batches (:mod:`.batch`,
:mod:`.report`) and the provenance recorded in every JSON sidecar (:mod:`.provenance`)."""
