"""The file layer: one scan through all stages (:mod:`.pipeline`), batches (:mod:`.batch`)
and the provenance recorded in every JSON sidecar (:mod:`.provenance`)."""
