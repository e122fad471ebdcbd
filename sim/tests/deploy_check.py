#!/usr/bin/env python3
"""Parse and validate the deploy files for sim/tests/deploy.rs; prints JSON.

  deploy_check.py k8s MANIFEST     every document validated against the Kubernetes API
                                   models (kubernetes client), unknown fields refused;
                                   prints {"kinds": [...], "objects": [...]}
  deploy_check.py workflow FILE    the GitHub Actions workflow parsed as YAML; prints it
"""
import json
import sys

import yaml


def strict(original, model_dict, path):
    """Every field of the manifest survives the round trip through the models: a
    misspelt or misplaced field (which the models drop) is an error."""
    if isinstance(original, dict):
        if not isinstance(model_dict, dict):
            sys.exit(f"{path}: not an object in the API schema")
        for k, v in original.items():
            if k not in model_dict:
                sys.exit(f"{path}.{k}: not a field of the API schema")
            strict(v, model_dict[k], f"{path}.{k}")
    elif isinstance(original, list):
        if not isinstance(model_dict, list) or len(model_dict) != len(original):
            sys.exit(f"{path}: not a list in the API schema")
        for i, (a, b) in enumerate(zip(original, model_dict)):
            strict(a, b, f"{path}[{i}]")
    elif original != model_dict and str(original) != str(model_dict):
        sys.exit(f"{path}: {original!r} reads back as {model_dict!r}")


def k8s(path):
    from kubernetes import client

    api = client.ApiClient()
    kinds, objects = [], []
    with open(path) as f:
        docs = [d for d in yaml.safe_load_all(f) if d is not None]
    for i, doc in enumerate(docs):
        version = doc.get("apiVersion", "")
        kind = doc.get("kind", "")
        # core v1 and batch/v1 objects are V1<Kind> models.
        if version.split("/")[-1] != "v1" or not hasattr(client, f"V1{kind}"):
            sys.exit(f"document {i}: no API model for {version} {kind}")
        try:
            obj = api._ApiClient__deserialize(doc, f"V1{kind}")
        except (ValueError, TypeError) as e:
            sys.exit(f"document {i} ({kind}): {e}")
        strict(doc, api.sanitize_for_serialization(obj), f"document {i} ({kind})")
        kinds.append(kind)
        objects.append(doc)
    print(json.dumps({"kinds": kinds, "objects": objects}))


def workflow(path):
    with open(path) as f:
        doc = yaml.safe_load(f)
    # YAML 1.1 reads the key `on` as the boolean true.
    if True in doc:
        doc["on"] = doc.pop(True)
    print(json.dumps(doc))


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "k8s":
        k8s(sys.argv[2])
    elif len(sys.argv) == 3 and sys.argv[1] == "workflow":
        workflow(sys.argv[2])
    else:
        sys.exit(__doc__)
