"""Flutter-derivative tables: the field's exchange format, and Roger models fitted to them.

- :mod:`~ident.tables.fd_table`: ``FlutterDerivativeTable`` (CSV in and out, 2 and 3 DOF);
- :mod:`~ident.tables.roger_table`: a table's Roger fit with its structure chosen by evidence;
- :mod:`~ident.tables.table_checks`: a table's warnings (sign typos and outliers, shifted damping
  derivatives, signs against the inter-relations, sparse rows, missing columns, noise, a flutter
  K outside the table);
- :mod:`~ident.tables.flutter_routes`: a section's flutter by the state space and the frequency
  domain, compared: the result, the route it rests on, the table's range, the divergence's basis,
  every caveat.
"""
